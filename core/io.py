"""Read and write any supported motion file, chosen by extension.

| extension            | read | write |
|----------------------|------|-------|
| ``.c3d``             | yes  | yes   |
| ``.bvh``, ``.bvh.gz``| yes  |       |
| ``.amc`` (+ ASF)     | yes  |       |
| ``.npz``             | yes  | yes   |
| ``.csv``             | yes  | yes   |

Writes are atomic (a temporary file in the same folder, then a rename), so an interrupted run
leaves any previous file intact, and they refuse to replace an existing file unless asked.
"""

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

from .errors import GapFillError, ParseError

READ_FORMATS = (".c3d", ".bvh", ".bvh.gz", ".amc", ".npz", ".csv")
#: the BVH files (plain and gzipped), and the armature takes
BVH_FORMATS = (".bvh", ".bvh.gz")
RIG_FORMATS = BVH_FORMATS + (".amc",)
WRITE_FORMATS = (".c3d", ".npz", ".csv")


def file_suffix(path):
    name = Path(path).name.lower()
    return ".bvh.gz" if name.endswith(".bvh.gz") else Path(name).suffix


def read_motion(path, asf=None, units=None, skip_frames=0, end_sites=False, up=None, bvh=None):
    """Read a motion file into a :class:`~mocap_gapfill.core.motion.Motion`.

    Parameters
    ----------
    path : str or Path
        A ``.c3d``, ``.bvh``, ``.bvh.gz``, ``.amc``, ``.npz`` or ``.csv`` file.
    asf : str or Path, optional
        Skeleton for an AMC; found beside it when omitted.
    units : str, optional
        BVH only: its unit (``m``, ``cm``, ``mm``, ``in``, ``cmu``); guessed when omitted.
    skip_frames : int
        Leading frames to drop (BVH reference poses).
    end_sites : bool
        BVH only: include End Site points.
    up : str, optional
        ``"y"`` or ``"z"``: the up axis of the file's data, whatever its header says (see
        :mod:`.upright`); default: the header's.
    bvh : BvhFile, optional
        BVH only: the file as :func:`~.formats.bvh.parse_bvh` gave it, for a caller that also
        reads its armature (:func:`read_rig_basis`) and parses it once.

    Raises
    ------
    ParseError
        The file is missing, unreadable, corrupt, truncated or of an unknown kind.

    Examples
    --------
    >>> from mocap_gapfill.core.io import read_motion
    >>> read_motion("no/such/file.c3d")
    Traceback (most recent call last):
    ...
    mocap_gapfill.core.errors.ParseError: no/such/file.c3d: no such file
    """
    path = Path(path)
    if not path.is_file():
        raise ParseError("no such file" if not path.exists() else "not a file", path)
    suffix = file_suffix(path)
    if suffix in BVH_FORMATS:
        from .formats.bvh import read_bvh

        motion = read_bvh(path, units=units, skip_frames=skip_frames, end_sites=end_sites,
                          bvh=bvh)
    elif suffix == ".amc":
        from .formats.asfamc import read_asf_amc

        motion = read_asf_amc(path, asf)
    elif suffix == ".c3d":
        from .formats.c3d import read_c3d

        motion = read_c3d(path)
    elif suffix == ".npz":
        from .formats.tabular import read_npz

        motion = read_npz(path)
    elif suffix == ".csv":
        from .formats.tabular import read_csv

        motion = read_csv(path)
    elif suffix == ".asf":
        raise ParseError("an ASF file holds a skeleton, not motion: read its AMC", path)
    else:
        raise ParseError(f"unknown file type {suffix or '(none)'}; readable: "
                         f"{', '.join(READ_FORMATS)}", path)
    if skip_frames and suffix not in BVH_FORMATS:
        if skip_frames > motion.n_frames:
            raise ParseError(f"cannot skip {skip_frames} of {motion.n_frames} frames", path)
        motion = motion.frame_range(skip_frames)
    if up is not None:
        from .upright import turn_up

        motion = turn_up(motion, up)
    return motion


def read_rig_take(path, skip_frames=0, asf=None):
    """A take as an armature: ``(rig, channels, location, fps)``; BVH through Blender's importer
    rules, ASF/AMC through the add-on's import (one bone per segment, quaternions)."""
    from .formats.bvh import read_bvh_rig
    from .rig import rig_from_motion

    suffix = file_suffix(path)
    if suffix not in RIG_FORMATS:
        raise ParseError(f"a {suffix or 'file'} holds no armature; armature takes: "
                         f"{', '.join(RIG_FORMATS)}", path)
    if suffix in BVH_FORMATS:
        return read_bvh_rig(path, skip_frames=skip_frames)
    motion = read_motion(path, asf=asf, skip_frames=skip_frames)
    return (*rig_from_motion(motion), motion.fps)


def read_rig_basis(path, skip_frames=0, asf=None, bvh=None):
    """:func:`read_rig_take`'s armature with its pose as basis matrices (frames, bones, 4, 4):
    ``(rig, basis, fps)``; a BVH's straight from its rotations, without Blender's channels
    (``bvh``: the file already parsed, as :func:`read_motion` takes it)."""
    from .formats.bvh import read_bvh_basis
    from .rig import basis_matrices

    if file_suffix(path) in BVH_FORMATS:
        return read_bvh_basis(path, skip_frames=skip_frames, bvh=bvh)
    rig, channels, location, fps = read_rig_take(path, skip_frames, asf)
    return rig, basis_matrices(rig, channels, location), fps


@contextmanager
def atomic_output(path, overwrite=False):
    """A temporary path beside ``path`` to write to; renamed onto ``path`` when the block ends
    without an error, removed otherwise. Refuses an existing ``path`` unless ``overwrite``.

    The temporary name ends with the target's suffix (ezc3d appends ``.c3d`` to names that lack
    it).
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise GapFillError(f"{path} exists; pass overwrite (--force) to replace it")
    if not path.parent.is_dir():
        raise GapFillError(f"folder {path.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".part{file_suffix(path)}",
                               dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp makes it readable by its owner alone: as the user's umask wants a new file
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask():
    """The process's file-creation mask: read where the system tells it (Linux), else set and
    set back."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_motion(motion, path, overwrite=False):
    """Write a motion to ``.c3d``, ``.npz`` or ``.csv`` (by extension), atomically.

    Raises
    ------
    GapFillError
        Unknown extension, an existing file without ``overwrite``, or data the format cannot hold.
    """
    path = Path(path)
    suffix = file_suffix(path)
    if suffix not in WRITE_FORMATS:
        raise GapFillError(f"cannot write {suffix or 'files without extension'}; writable: "
                           f"{', '.join(WRITE_FORMATS)}")
    with atomic_output(path, overwrite) as tmp:
        if suffix == ".c3d":
            from .formats.c3d import write_c3d

            write_c3d(motion, tmp)
        else:
            from .formats import tabular

            with open(tmp, "wb") as handle:
                (tabular.write_npz if suffix == ".npz" else tabular.write_csv)(motion, handle)
    return path
