"""C3D reader and writer (through ezc3d), with the guards its native code needs.

ezc3d aborts or crashes the whole process on some inputs (a corrupt file, a write without a
frame rate), which inside Blender would take the user's session down. Worse, some corrupt files
damage its memory without crashing at once (a later read then crashes: seen in batch fuzzing).
So every file is checked structurally in pure Python (:func:`precheck`), then read by ezc3d in a
short-lived child process whose arrays come back through a temporary ``.npz``: a crash or a hang
there becomes a :class:`ParseError`. (Each read's temporary folder goes with the read; those a
killed process left - a batch worker stopped by Ctrl-C, a Blender that crashed - go with the next
read.) Everything ezc3d needs is validated before it writes.

Gaps: a sample is missing when ezc3d gives NaN (its encoding of residual < 0), when the residual is
negative, or when the point is exactly (0, 0, 0) (how some systems write gaps). A present sample
with residual exactly 0 was interpolated by some program: it reads as *filled*.
"""

import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..errors import GapFillError, ParseError
from ..motion import Motion, rigid_marker_pairs, y_up_to_z_up

#: C3D frame counts are 16-bit in the header: more frames come back truncated from ezc3d
MAX_FRAMES = 65535
_UNITS = {"mm": ("mm", 0.001), "cm": ("cm", 0.01), "m": ("m", 1.0), "in": ("in", 0.0254)}
#: seconds one read may take in the child process
READ_TIMEOUT = 120
#: the temporary folders the reads' arrays pass through (in the system's temporary folder)
READ_FOLDER_PREFIX = "mocap_gapfill_c3d_"
#: address space (MB) the child process may take beyond its start and 32x the file's size
READ_MEMORY_MB = 2048
#: the child process: read with ezc3d, save what we need (no pickle), exit 3 on a reported error
_READER = r"""
import os, sys
for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[name] = "1"  # a read needs no threads (and each one reserves memory)
try:  # a corrupt file can make ezc3d allocate without bound: cap this process's memory
    import resource
    with open("/proc/self/status") as status:
        used = next(int(l.split()[1]) << 10 for l in status if l.startswith("VmSize:"))
    cap = used + (READ_MEMORY_MB << 20) + 32 * os.path.getsize(sys.argv[1])
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
except Exception:
    pass  # no /proc (macOS, Windows): no cap
import numpy as np
import ezc3d
try:
    c3d = ezc3d.c3d(sys.argv[1])
    point = c3d["parameters"]["POINT"]
    labels = []
    for key in ["LABELS"] + ["LABELS%d" % i for i in range(2, 100)]:
        if key not in point:
            break
        labels.extend(str(v) for v in point[key]["value"])
    def text(name, default):
        value = point.get(name, {}).get("value")
        return str(value[0]) if value is not None and len(value) else default
    try:
        rate = float(point["RATE"]["value"][0])
    except Exception:
        rate = float("nan")
    residuals = c3d["data"].get("meta_points", {}).get("residuals")
    np.savez(sys.argv[2], points=np.asarray(c3d["data"]["points"], dtype=np.float64),
             residuals=np.asarray(residuals if residuals is not None else np.zeros((0, 0, 0))),
             labels=np.array(labels, dtype=str), rate=np.float64(rate),
             units=np.str_(text("UNITS", "mm")), y_screen=np.str_(text("Y_SCREEN", "+Z")))
except Exception as exc:
    print(exc, file=sys.stderr)
    sys.exit(3)
"""
#: observed samples get this residual on write (their true residual is not kept in a Motion)
OBSERVED_RESIDUAL = 1.0


def _float(raw, processor):
    if processor == 85:  # DEC: word-swapped, exponent bias off by 2
        return struct.unpack("<f", raw[2:4] + raw[0:2])[0] / 4.0
    return struct.unpack(">f" if processor == 86 else "<f", raw)[0]


def _parameter_records(data, pstart, pend, i16, path):
    """The groups (``{id: name}``) and parameters (``{(group id, name): (type, dims, raw)}``)
    of a C3D parameter section (bytes ``pstart``-``pend`` of ``data``), every record checked
    to lie inside the section and to point forward."""
    groups, params = {}, {}
    pos = pstart + 4
    while pos + 2 <= pend:
        nlen = struct.unpack("b", data[pos:pos + 1])[0]
        gid = struct.unpack("b", data[pos + 1:pos + 2])[0]
        if nlen == 0:
            break
        n = abs(nlen)
        off_pos = pos + 2 + n
        if off_pos + 2 > pend:
            raise ParseError("parameter record runs past the parameter section", path)
        name = data[pos + 2:off_pos].decode("latin-1").strip().upper()
        step = i16.unpack_from(data, off_pos)[0]
        body = off_pos + 2
        if gid < 0:
            if body + 1 > pend or body + 1 + data[body] > pend:
                raise ParseError(f"group {name!r} runs past the parameter section", path)
            groups[-gid] = name
        else:
            if body + 2 > pend:
                raise ParseError(f"parameter {name!r} runs past the parameter section", path)
            dtype = struct.unpack("b", data[body:body + 1])[0]
            ndims = data[body + 1]
            if dtype not in (-1, 1, 2, 4):
                raise ParseError(f"parameter {name!r} has unknown data type {dtype}", path)
            if ndims > 7 or body + 2 + ndims > pend:
                raise ParseError(f"parameter {name!r} has bad dimensions", path)
            dims = list(data[body + 2:body + 2 + ndims])
            count = int(np.prod(dims)) if dims else 1
            value_at = body + 2 + ndims
            end = value_at + count * abs(dtype)
            if end + 1 > pend or end + 1 + data[end] > pend:
                raise ParseError(f"parameter {name!r} runs past the parameter section", path)
            params[(gid, name)] = (dtype, dims, data[value_at:end])
        if step == 0:
            break
        nxt = off_pos + step
        if nxt <= pos or nxt > pend:
            raise ParseError("parameter records point backwards or outside the section", path)
        pos = nxt
    return groups, params


def precheck(path):
    """Check a C3D file's structure without native code; raise :class:`ParseError` if unsafe.

    Checks the signature, the processor type, that every parameter record lies inside the
    parameter section and moves forward, that dimensions and types are valid, and that the file
    is long enough for the point and analog data the header and parameters announce.

    Returns
    -------
    dict
        ``points``, ``frames``, ``rate`` as announced (for messages and tests).
    """
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ParseError(f"cannot read file ({exc.strerror})", path) from None
    size = len(data)
    if size == 0:
        raise ParseError("empty file", path)
    if size < 1024:
        raise ParseError(f"only {size} bytes: too short for a C3D file (truncated?)", path)
    if data[1] != 0x50:
        raise ParseError("not a C3D file (no C3D signature in the header)", path)
    pblock = data[0]
    if pblock < 2:
        raise ParseError(f"bad parameter block pointer {pblock}", path)
    pstart = (pblock - 1) * 512
    if pstart + 4 > size:
        raise ParseError("parameter section lies beyond the end of the file (truncated?)", path)
    processor = data[pstart + 3]
    if processor not in (84, 85, 86):
        raise ParseError(f"unknown processor type {processor} in the parameter section", path)
    endian = ">" if processor == 86 else "<"
    pend = min(size, pstart + max(1, data[pstart + 2]) * 512)
    i16 = struct.Struct(endian + "h")
    u16 = struct.Struct(endian + "H")

    groups, params = _parameter_records(data, pstart, pend, i16, path)

    def param_int(group, name):
        for (gid, pname), (dtype, dims, raw) in params.items():
            if groups.get(gid) == group and pname == name and dtype == 2 and len(raw) >= 2:
                return u16.unpack_from(raw)[0]
        return None

    header_points = u16.unpack_from(data, 2)[0]
    analog_per_frame = u16.unpack_from(data, 4)[0]
    first, last = u16.unpack_from(data, 6)[0], u16.unpack_from(data, 8)[0]
    scale = _float(data[12:16], processor)
    data_start = u16.unpack_from(data, 16)[0]
    rate = _float(data[20:24], processor)
    if first == 0 or last < first - 1:
        raise ParseError(f"bad frame range {first}..{last} in the header", path)
    frames = last - first + 1
    points = max(header_points, param_int("POINT", "USED") or 0)
    param_start = param_int("POINT", "DATA_START")
    starts = [s for s in (data_start, param_start) if s]
    if not starts or min(starts) <= pblock - 1:
        raise ParseError("bad data start block", path)
    analog = max(analog_per_frame, (param_int("ANALOG", "USED") or 0))
    bytes_per = 4 if scale < 0 or not np.isfinite(scale) else 2
    needed = (max(starts) - 1) * 512 + frames * (points * 4 + analog) * bytes_per
    if needed > size:
        raise ParseError(f"truncated: {frames} frames of {points} points need {needed} bytes, "
                         f"the file has {size}", path)
    if not np.isfinite(rate) or rate < 0:
        raise ParseError(f"bad frame rate {rate}", path)
    return {"points": points, "frames": frames, "rate": rate}


def _labels(raw, count):
    """Point names from the file's labels: prefixes dropped where that keeps them unique."""
    raw = [label.strip() for label in raw[:count]] + [""] * (count - len(raw))
    raw = [label if label else f"P{i}" for i, label in enumerate(raw)]
    short = [label.split(":")[-1] or label for label in raw]  # "Male:LFHD" -> "LFHD"
    names = [s if short.count(s) == 1 else r for s, r in zip(short, raw)]
    seen = {}
    for i, n in enumerate(names):  # duplicated labels in the file: keep all, numbered
        if names.count(n) > 1:
            seen[n] = seen.get(n, 0) + 1
            names[i] = f"{n}#{seen[n]}"
    return names


def reader_script():
    """The child's Python code (:data:`_READER` with the memory cap filled in)."""
    return _READER.replace("READ_MEMORY_MB", str(READ_MEMORY_MB))


def _run_reader(path, out):
    """Run :data:`_READER` on ``path`` in a new Python process: (exit code, stderr).

    Raises ``subprocess.TimeoutExpired`` after :data:`READ_TIMEOUT` seconds. (The fuzzing harness,
    tools/fuzz.py, swaps in a forked child running the same code, to read faster.)
    """
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    proc = subprocess.run([sys.executable, "-c", reader_script(), str(path), str(out)], env=env,
                          capture_output=True, text=True, timeout=READ_TIMEOUT)
    return proc.returncode, proc.stderr


def _read_isolated(path):
    """ezc3d's read in a child process: the arrays, or a ParseError (also on a crash/hang)."""
    _sweep_stale_reads()
    with tempfile.TemporaryDirectory(prefix=READ_FOLDER_PREFIX) as tmp:
        out = Path(tmp) / "read.npz"
        try:
            code, stderr = _run_reader(path, out)
        except subprocess.TimeoutExpired:
            raise ParseError(f"reading took over {READ_TIMEOUT} s (corrupt file?)", path) from None
        if code == 3:
            reason = stderr.strip().splitlines()[-1] if stderr.strip() else "unknown"
            raise ParseError(f"unreadable C3D ({reason})", path)
        if code != 0 or not out.is_file():
            raise ParseError(f"the C3D library crashed on this file (exit {code}): "
                             "it is corrupt", path)
        with np.load(out, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}


def _sweep_stale_reads():
    """Remove the read folders a killed process left behind (a read's own folder goes when it
    ends, but not when its process is killed mid-read): those older than twice
    :data:`READ_TIMEOUT`, which no read still running can be. Folders it may not remove (another
    user's) are left alone."""
    oldest = time.time() - 2 * READ_TIMEOUT
    for folder in Path(tempfile.gettempdir()).glob(READ_FOLDER_PREFIX + "*"):
        try:
            stale = folder.is_dir() and folder.stat().st_mtime < oldest
        except OSError:  # gone meanwhile
            continue
        if stale:
            shutil.rmtree(folder, ignore_errors=True)


def read_c3d(path):
    """Read a C3D file into a :class:`Motion` of markers (see the module docstring for gaps)."""
    info = precheck(path)
    data = _read_isolated(path)
    points = data["points"]
    if points.ndim != 3 or points.shape[0] < 3:
        raise ParseError("no point data", path)
    rate = float(data["rate"])
    if not np.isfinite(rate):
        rate = info["rate"]
    if not np.isfinite(rate) or rate <= 0:
        raise ParseError(f"bad frame rate {rate}", path)
    unit_text = str(data["units"]).strip().lower()
    if unit_text not in _UNITS:
        raise ParseError(f"unknown point units {unit_text!r}", path)
    units, scale = _UNITS[unit_text]
    pos = points[:3].transpose(2, 1, 0) * scale  # (frames, points, 3)
    residuals = data["residuals"]
    missing = ~np.isfinite(pos).all(axis=2) | np.all(pos == 0, axis=2)
    filled = np.zeros_like(missing)
    if residuals.ndim == 3 and residuals.shape[1:] == points.shape[1:]:
        res = residuals[0].T
        missing |= res < 0
        filled = (res == 0) & ~missing
    pos[missing] = np.nan
    up = "y" if str(data["y_screen"]).strip().upper() == "+Y" else "z"
    if up == "y":
        pos = y_up_to_z_up(pos)
    names = _labels(data["labels"].tolist(), pos.shape[1])
    return Motion(
        positions=pos,
        names=tuple(names),
        fps=rate,
        limbs=rigid_marker_pairs(pos),
        source=str(path),
        source_format="c3d",
        units=units,
        up_axis=up,
        filled=filled,
    )


def check_writable(motion):
    """Raise :class:`GapFillError` unless ezc3d can write this motion safely and faithfully."""
    frames, points = motion.n_frames, motion.n_points
    if frames < 1:
        raise GapFillError("cannot write a C3D file with no frames")
    if frames > MAX_FRAMES:
        raise GapFillError(f"C3D holds at most {MAX_FRAMES} frames, this motion has {frames}: "
                           "write .npz or .csv, or split the take")
    if points < 1:
        raise GapFillError("cannot write a C3D file with no points")
    if not (np.isfinite(motion.fps) and 0 < motion.fps < 1e6):
        raise GapFillError(f"bad frame rate {motion.fps} for C3D")
    bad = [n for n in motion.names if not n.isascii() or not n.isprintable()]
    if bad:
        raise GapFillError(f"C3D labels must be printable ASCII: {', '.join(map(repr, bad))}")
    with np.errstate(invalid="ignore"):
        if np.nanmax(np.abs(motion.positions), initial=0) > 1e6:
            raise GapFillError("positions over 1000 km: wrong units?")


def write_c3d(motion, path):
    """Write a motion as a float C3D in millimetres, Z up.

    Residuals: missing samples -1, filled samples 0 (the C3D convention for interpolated points),
    observed samples :data:`OBSERVED_RESIDUAL`.
    """
    check_writable(motion)
    import ezc3d

    pos = motion.positions * 1000.0
    missing = motion.missing
    data = np.ones((4, motion.n_points, motion.n_frames))
    data[:3] = np.where(missing[..., None], np.nan, pos).transpose(2, 1, 0)
    residuals = np.full((1, motion.n_points, motion.n_frames), OBSERVED_RESIDUAL)
    if motion.filled is not None:
        residuals[0][motion.filled.T] = 0.0
    residuals[0][missing.T] = -1.0
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [float(motion.fps)]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(motion.names)
    c3d["data"]["points"] = data
    c3d["data"]["meta_points"] = {
        "residuals": residuals,
        "camera_masks": np.zeros((7, motion.n_points, motion.n_frames), dtype=bool),
    }
    c3d.add_parameter("POINT", "UNITS", ["mm"])
    c3d.add_parameter("POINT", "X_SCREEN", ["+X"])
    c3d.add_parameter("POINT", "Y_SCREEN", ["+Z"])
    c3d.write(str(path))


__all__ = ["read_c3d", "write_c3d", "precheck", "check_writable", "MAX_FRAMES"]
