"""NPZ and CSV: plain position tables, our own interchange formats.

NPZ arrays: ``positions`` (frames, points, 3) float64 metres Z-up with NaN for missing, ``names``
(unicode), ``fps``; also ``parents`` (empty for markers), ``limbs``, ``filled``, ``units``,
``up_axis``, ``rest`` (a skeleton's own rest pose, (points, 3); empty without one),
``format_version``. Loaded with ``allow_pickle=False``.

CSV: a ``# mocap-gapfill csv 1 fps=<fps>`` line, a header ``frame,<name>.x,<name>.y,<name>.z,...``,
then one row per frame in metres; an empty cell is a missing sample.
"""

import csv
import io
import zipfile

import numpy as np

from ..errors import ParseError
from ..motion import Motion, rigid_marker_pairs, skeleton_limbs
from . import read_text_bytes

NPZ_VERSION = 1


def write_npz(motion, fileobj):
    np.savez_compressed(
        fileobj,
        format_version=np.int64(NPZ_VERSION),
        positions=motion.positions,
        names=np.array(motion.names, dtype=str),
        fps=np.float64(motion.fps),
        parents=np.array(motion.parents if motion.parents is not None else [], dtype=np.int64),
        limbs=motion.limbs,
        filled=motion.filled if motion.filled is not None else np.zeros((0, 0), dtype=bool),
        units=np.str_(motion.units),
        up_axis=np.str_(motion.up_axis),
        rest=motion.rest if motion.rest is not None else np.zeros((0, 3)),
    )


def load_arrays(path, max_bytes, what="a readable .npz"):
    """The arrays of an ``.npz`` file, never unpickled; :class:`ParseError` ("not ``what``") if it
    is not one, or if its members would take more than ``max_bytes`` (checked before anything is
    loaded)."""
    try:
        with zipfile.ZipFile(path) as archive:
            if sum(i.file_size for i in archive.infolist()) > max_bytes:
                raise ParseError(f"too large to load (over {max_bytes >> 20} MB of arrays)", path)
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except ParseError:
        raise
    except Exception as exc:  # zipfile and numpy raise many kinds on a corrupt file
        raise ParseError(f"not {what} ({type(exc).__name__}: {exc})", path) from None
    # members not named .npy come back as raw bytes: not ours
    return {k: v for k, v in arrays.items() if isinstance(v, np.ndarray)}


def scalar(arrays, key, kinds, path, default=None):
    """A one-number array of one of the dtype ``kinds`` (e.g. ``"iu"``) as a Python number."""
    if key not in arrays:
        if default is None:
            raise ParseError(f"missing array {key!r}", path)
        return default
    value = arrays[key]
    if value.size != 1 or value.dtype.kind not in kinds:
        raise ParseError(f"{key} must be one number, got {value.dtype} {value.shape}", path)
    return value.reshape(()).item()


def strings(arrays, key, shape, path, unique=False):
    """A unicode array of this shape as a list of non-empty strings (valid code points only)."""
    value = arrays.get(key)
    if value is None or value.dtype.kind != "U" or value.shape != shape:
        raise ParseError(f"{key} must be {shape[0] if shape else 1} strings", path)
    codes = np.frombuffer(value.tobytes(), dtype=np.uint32)
    if codes.size and (codes.max() > 0x10FFFF or ((codes >= 0xD800) & (codes < 0xE000)).any()):
        raise ParseError(f"{key} holds invalid characters", path)
    out = value.tolist()
    out = [out] if isinstance(out, str) else out
    if not all(out) or (unique and len(set(out)) != len(out)):
        raise ParseError(f"{key} must be non-empty{' and unique' if unique else ''}", path)
    return out


#: what a motion .npz may hold in arrays
MAX_NPZ_BYTES = 4 << 30


def read_npz(path):
    arrays = load_arrays(path, MAX_NPZ_BYTES)
    version = scalar(arrays, "format_version", "iu", path, NPZ_VERSION)
    if version > NPZ_VERSION:
        raise ParseError(f"written by a newer version (format {version}); update mocap-gapfill",
                         path)
    positions = arrays.get("positions")
    if positions is None or positions.dtype.kind not in "fiu" or positions.ndim != 3 or (
            positions.shape[-1] != 3):
        raise ParseError("positions must be numbers of shape (frames, points, 3)", path)
    names = strings(arrays, "names", (positions.shape[1],), path)
    parents = arrays.get("parents", np.zeros(0, dtype=np.int64))
    if parents.dtype.kind not in "iu" or parents.ndim != 1:
        raise ParseError("parents must be integers", path)
    parents = tuple(parents.tolist()) if parents.size else None
    filled = arrays.get("filled")
    units = strings(arrays, "units", (), path)[0] if "units" in arrays else "m"
    up_axis = strings(arrays, "up_axis", (), path)[0] if "up_axis" in arrays else "z"
    rest = arrays.get("rest")
    if rest is not None and rest.dtype.kind not in "fiu":
        raise ParseError("rest must be numbers", path)
    try:
        return Motion(
            positions=positions.astype(np.float64),
            names=tuple(names),
            fps=scalar(arrays, "fps", "fiu", path),
            parents=parents,
            limbs=arrays.get("limbs", skeleton_limbs(parents) if parents else np.zeros((0, 2))),
            source=str(path),
            source_format="npz",
            units=units,
            up_axis=up_axis,
            filled=filled if filled is not None and filled.size else None,
            rest=rest if rest is not None and rest.size else None,
        )
    except (ValueError, TypeError) as exc:
        raise ParseError(str(exc), path) from None


def write_csv(motion, fileobj):
    text = io.TextIOWrapper(fileobj, encoding="utf-8", newline="")
    text.write(f"# mocap-gapfill csv 1 fps={motion.fps!r}\n")
    writer = csv.writer(text)
    writer.writerow(["frame"] + [f"{n}.{a}" for n in motion.names for a in "xyz"])
    flat = motion.positions.reshape(motion.n_frames, -1)
    for f, row in enumerate(flat):
        writer.writerow([f] + ["" if np.isnan(v) else repr(float(v)) for v in row])
    text.flush()
    text.detach()


def read_csv(path):
    try:
        lines = read_text_bytes(path).decode("utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise ParseError(f"cannot read CSV ({exc})", path) from None
    if not lines or not lines[0].startswith("# mocap-gapfill csv"):
        raise ParseError("not a mocap-gapfill CSV (first line must be '# mocap-gapfill csv 1 "
                         "fps=...')", path, 1)
    try:
        fps = float(lines[0].split("fps=", 1)[1].split()[0])
    except (IndexError, ValueError):
        raise ParseError("no fps= on the first line", path, 1) from None
    rows = list(csv.reader(lines[1:]))
    if not rows:
        raise ParseError("no header row", path, 2)
    header = rows[0]
    if not header or header[0] != "frame" or (len(header) - 1) % 3:
        raise ParseError("header must be frame,<name>.x,<name>.y,<name>.z,...", path, 2)
    names = []
    for i in range(1, len(header), 3):
        base = [h.rsplit(".", 1) for h in header[i:i + 3]]
        if [b[-1] for b in base] != ["x", "y", "z"] or len({b[0] for b in base}) != 1:
            raise ParseError(f"columns {header[i:i + 3]} are not one point's x, y, z", path, 2)
        names.append(base[0][0])
    values = np.full((len(rows) - 1, len(header) - 1), np.nan)
    for r, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise ParseError(f"{len(row)} cells, expected {len(header)}", path, r + 3)
        try:
            values[r] = [float(v) if v.strip() else np.nan for v in row[1:]]
        except ValueError:
            raise ParseError("non-numeric cell", path, r + 3) from None
    positions = values.reshape(len(values), len(names), 3)
    try:
        return Motion(positions=positions, names=tuple(names), fps=fps,
                      limbs=rigid_marker_pairs(positions), source=str(path), source_format="csv")
    except ValueError as exc:
        raise ParseError(str(exc), path) from None
