"""Seed files for fuzzing the readers, and the crashers found, stored as edits of a seed.

The seeds are small valid files made at run time from the real data in ../shared/data (cut to a
few frames, or written by our own writers), so no motion data is copied into the repository. A
crasher is kept as ``tests/fuzz_crashers/<format>-<id>.json``: the seed's name and the byte edits
that turn the seed into the crashing input (``encode`` / ``decode``). Used by tools/fuzz.py (the
fuzzing harness) and tests/test_fuzz_crashers.py (the regression tests).
"""

import dataclasses
import difflib
import gzip
import hashlib
import io
import json
import tempfile
from pathlib import Path

CRASHERS = Path(__file__).resolve().parent / "fuzz_crashers"
FORMATS = ("c3d", "bvh", "asf", "amc", "kb", "npz", "csv")


def _bvh_cut(text, frames):
    head, _, motion = text.partition("MOTION")
    lines = motion.strip().splitlines()
    body = [ln for ln in lines if not ln.startswith(("Frames:", "Frame Time:"))][:frames]
    time = next(ln for ln in lines if ln.startswith("Frame Time:"))
    return f"{head}MOTION\nFrames: {len(body)}\n{time}\n" + "\n".join(body) + "\n"


def _amc_cut(text, frames):
    keep = []
    for line in text.splitlines():
        if line.strip().isdigit() and int(line) > frames:
            break
        keep.append(line)
    return "\n".join(keep) + "\n"


def seeds(fmt, data):
    """{name: bytes} of small valid files of one format, made from the real data."""
    data = Path(data)
    if fmt == "bvh":
        mb = (data / "cmu/bvh/mb_friendly/01_01.bvh").read_text()
        daz = gzip.decompress((data / "cmu/bvh/daz_friendly/03/03_02.bvh.gz").read_bytes())
        return {"mb_01_01": _bvh_cut(mb, 12).encode(), "daz_03_02": _bvh_cut(daz.decode(), 6).encode()}
    if fmt == "asf":
        return {"09": (data / "cmu/asfamc/09/09.asf").read_bytes(),
                "01": (data / "cmu/asfamc/01/01.asf").read_bytes()}
    if fmt == "amc":
        return {"09_06": _amc_cut((data / "cmu/asfamc/09/09_06.amc").read_text(), 8).encode()}
    if fmt == "c3d":
        return {name: _written(data / path, frames, "c3d") for name, path, frames in (
            ("85_02", "cmu/c3d/85_02.c3d", 24), ("01_01", "cmu/c3d/01_01.c3d", 24))}
    if fmt in ("npz", "csv"):
        return {name: _written(data / path, frames, fmt) for name, path, frames in (
            ("85_02", "cmu/c3d/85_02.c3d", 12), ("09_06", "cmu/asfamc/09/09_06.amc", 8))}
    if fmt == "kb":
        return {"markers": _kb_bytes(data / "cmu/c3d/85_02.c3d", 30),
                "skeleton": _kb_bytes(data / "cmu/asfamc/09/09_06.amc", 20)}
    raise ValueError(f"unknown format {fmt}")


def _file_bytes(save, name):
    """The bytes ``save(path)`` writes to a file called ``name``."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / name
        save(out)
        return out.read_bytes()


def _written(path, frames, fmt):
    """The first frames of a real file, written by our own writer in format ``fmt``."""
    from mocap_gapfill.core.io import read_motion, write_motion

    motion = read_motion(path).frame_range(0, frames)
    return _file_bytes(lambda out: write_motion(motion, out), f"seed.{fmt}")


def _kb_bytes(path, frames):
    from mocap_gapfill.core.io import read_motion
    from mocap_gapfill.core.kb import kb_from_motions

    kb = kb_from_motions([read_motion(path).frame_range(0, frames)])
    kb = dataclasses.replace(kb, sources=(path.name,))  # the same bytes wherever the data is
    return _file_bytes(kb.save, "seed.npz")


def partner(fmt, data):
    """(suffix, bytes) of the file a fuzzed ASF is read with (an AMC) and the skeleton a fuzzed
    AMC is read with (an ASF); None for the other formats."""
    data = Path(data)
    if fmt == "asf":
        return ".amc", _amc_cut((data / "cmu/asfamc/09/09_06.amc").read_text(), 8).encode()
    if fmt == "amc":
        return ".asf", (data / "cmu/asfamc/09/09.asf").read_bytes()
    return None


def input_paths(fmt, folder, data):
    """Where an input of ``fmt`` goes in ``folder``, and the partner file it is read with
    (written there; None for formats read alone)."""
    folder = Path(folder)
    path = folder / ("input.npz" if fmt == "kb" else f"input.{fmt}")
    pair = partner(fmt, data)
    if pair is None:
        return path, None
    suffix, raw = pair
    (folder / f"partner{suffix}").write_bytes(raw)
    return path, folder / f"partner{suffix}"


def read_as_user(fmt, path, partner=None):
    """Read one input the way a user's file is read (the fuzz target); returns a size."""
    from mocap_gapfill.core.io import read_motion
    from mocap_gapfill.core.kb import load_kb, match_names

    if fmt == "kb":
        kb = load_kb(path)
        kb.reference_for(kb.names)
        match_names(kb, kb.names)
        return kb.size
    if fmt == "asf":
        return read_motion(partner, asf=path).n_frames
    if fmt == "amc":
        return read_motion(path, asf=partner).n_frames
    return read_motion(path).n_frames


def encode(seed, data):
    """The edits (JSON-able) that turn ``seed`` into ``data``."""
    ops = difflib.SequenceMatcher(None, seed, data, autojunk=False).get_opcodes()
    return [[i1, i2, data[j1:j2].hex()] for tag, i1, i2, j1, j2 in ops if tag != "equal"]


def decode(seed, edits):
    """Apply :func:`encode`'s edits to ``seed``."""
    out, pos = io.BytesIO(), 0
    for i1, i2, new in edits:
        out.write(seed[pos:i1])
        out.write(bytes.fromhex(new))
        pos = i2
    out.write(seed[pos:])
    return out.getvalue()


def save_crasher(fmt, seed_name, seed, data, note):
    """Keep a crashing input as edits of its seed; returns the file written."""
    CRASHERS.mkdir(exist_ok=True)
    key = hashlib.sha1(data).hexdigest()[:12]
    path = CRASHERS / f"{fmt}-{key}.json"
    path.write_text(json.dumps({"format": fmt, "seed": seed_name, "edits": encode(seed, data),
                                "note": note}, indent=1) + "\n")
    return path


def crashers():
    """(path, record) of every kept crasher."""
    return [(p, json.loads(p.read_text())) for p in sorted(CRASHERS.glob("*.json"))]
