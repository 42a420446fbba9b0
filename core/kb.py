"""Knowledge base: normalised clean poses, saved as a versioned ``.npz`` (no pickle).

File arrays: ``format_version``, ``poses`` float32 (poses, points, 3) metres in the normalised
frame, ``names``, ``fps``, ``limbs``, ``sources`` (one string per source file), ``source_index``
(int32 per pose: which source), ``reference`` (JSON: root/left/right point names); built from
BVH takes also ``bones`` and ``turns`` float32 (poses, bones, 4): each bone's
rotation in its parent's frame with the rest axes taken out (:func:`~.rig.aligned_turns`), as
quaternions (x, y, z, w), for filling armature gaps in rotation space.
"""

import fnmatch
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import GapFillError, ParseError
from .formats.bvh import parse_bvh
from .formats.tabular import load_arrays, scalar, strings
from .io import (BVH_FORMATS, READ_FORMATS, RIG_FORMATS, atomic_output, file_suffix,
                 read_motion, read_rig_basis)
from .normalize import find_reference, frames_of, normalize
from .upright import upright_warning

KB_VERSION = 1
#: a cap on what a KB file may hold, checked before any array is loaded
MAX_KB_BYTES = 8 << 30


@dataclass(frozen=True, eq=False)
class KnowledgeBase:
    """Clean normalised poses and what they came from.

    Parameters
    ----------
    poses : ndarray, shape (poses, points, 3), float32
    names : tuple of str
    fps : float
    limbs : ndarray, shape (limbs, 2), int
    sources : tuple of str
    source_index : ndarray, shape (poses,), int32
    bones : tuple of str
        Bones with ``turns`` (empty for marker knowledge bases).
    turns : ndarray, shape (poses, bones, 4), float32, or None
        Quaternions (x, y, z, w) of :func:`~.rig.aligned_turns`, per pose and bone.
    """

    poses: np.ndarray
    names: tuple
    fps: float
    limbs: np.ndarray
    sources: tuple
    source_index: np.ndarray
    bones: tuple = ()
    turns: np.ndarray = None

    @property
    def size(self):
        return self.poses.shape[0]

    @property
    def reference(self):
        return find_reference(self.names)

    def reference_for(self, names):
        """The :class:`~mocap_gapfill.core.normalize.Reference` of a query's point set, which must orient poses by the same
        points as this knowledge base (raises :class:`GapFillError` naming them otherwise)."""
        mine = self.reference.to_dict(self.names)
        lacking = [n for group in mine.values() for n in group if n not in names]
        if lacking:
            raise GapFillError(f"the knowledge base orients poses by {', '.join(lacking)}, which "
                               "this motion does not have")
        theirs = find_reference(list(names))
        if theirs.to_dict(list(names)) != mine:
            raise GapFillError("the motion and the knowledge base orient poses by different points")
        return theirs

    def summary(self):
        return {"poses": self.size, "points": len(self.names), "fps": self.fps,
                "sources": len(self.sources), "names": list(self.names),
                "bones with rotations": len(self.bones)}

    def subset(self, keep):
        """The poses where ``keep`` (poses,) is True, sources unchanged."""
        return KnowledgeBase(self.poses[keep], self.names, self.fps, self.limbs, self.sources,
                             self.source_index[keep], self.bones,
                             None if self.turns is None else self.turns[keep])

    def save(self, path, overwrite=False, compact=False):
        """Write atomically to ``path`` (``.npz``); ``compact``: poses as float16 (0.5 mm steps
        at 1 m), compressed, for knowledge bases shipped with the extension."""
        write = np.savez_compressed if compact else np.savez
        turns = {} if self.turns is None else dict(
            bones=np.array(self.bones, dtype=str),
            turns=self.turns.astype(np.float16 if compact else np.float32))
        with atomic_output(path, overwrite) as tmp, open(tmp, "wb") as handle:
            write(handle, **turns, format_version=np.int64(KB_VERSION),
                  poses=self.poses.astype(np.float16 if compact else np.float32),
                  names=np.array(self.names, dtype=str), fps=np.float64(self.fps),
                  limbs=np.asarray(self.limbs, dtype=np.int64),
                  sources=np.array(self.sources, dtype=str),
                  source_index=self.source_index.astype(np.int32),
                  reference=np.str_(json.dumps(self.reference.to_dict(self.names))))
        return Path(path)


def load_kb(path):
    """Load and check a knowledge-base file; :class:`ParseError` on anything unexpected."""
    path = Path(path)
    if not path.is_file():
        raise ParseError("no such knowledge-base file", path)
    if path.stat().st_size == 0:
        raise ParseError("empty knowledge-base file (0 bytes)", path)
    arrays = load_arrays(path, MAX_KB_BYTES, "a knowledge-base file")
    needed = {"format_version", "poses", "names", "fps", "limbs", "sources", "source_index"}
    lacking = needed - set(arrays)
    if lacking:
        raise ParseError(f"not a knowledge-base file: lacks {', '.join(sorted(lacking))}", path)
    version = scalar(arrays, "format_version", "iu", path)
    if version > KB_VERSION:
        raise ParseError(f"knowledge base format {version} is newer than this version of "
                         f"mocap-gapfill understands ({KB_VERSION}): update mocap-gapfill", path)
    if version < 1:
        raise ParseError(f"bad format_version {version}", path)
    poses = arrays["poses"]
    if poses.dtype not in (np.float32, np.float16) or poses.ndim != 3 or poses.shape[2] != 3 \
            or not poses.size:
        raise ParseError(f"poses must be float32 or float16 (poses, points, 3), got "
                         f"{poses.dtype} {poses.shape}", path)
    poses = poses.astype(np.float32, copy=False)
    names = strings(arrays, "names", (poses.shape[1],), path, unique=True)
    if not np.isfinite(poses).all():
        raise ParseError("poses contain NaN or infinite values", path)
    fps = float(scalar(arrays, "fps", "fiu", path))
    limbs = arrays["limbs"]
    index = arrays["source_index"]
    if not (np.isfinite(fps) and fps > 0):
        raise ParseError(f"bad fps {fps}", path)
    if limbs.dtype.kind != "i" or limbs.ndim != 2 or limbs.shape[1] != 2 or (limbs.size and (
            limbs.min() < 0 or limbs.max() >= len(names))):
        raise ParseError("bad limbs array", path)
    sources = strings(arrays, "sources", (arrays["sources"].size,), path)
    if not sources:
        raise ParseError("sources must be a list of strings", path)
    if index.shape != (len(poses),) or index.dtype.kind != "i" or (
            index.min() < 0 or index.max() >= len(sources)):
        raise ParseError("bad source_index array", path)
    bones, turns = (), None
    if "turns" in arrays or "bones" in arrays:
        turns = arrays.get("turns")
        if turns is None or "bones" not in arrays:
            raise ParseError("bone rotations need both 'bones' and 'turns'", path)
        bones = strings(arrays, "bones", (arrays["bones"].size,), path, unique=True)
        if (turns.dtype not in (np.float32, np.float16)
                or turns.shape != (len(poses), len(bones), 4)):
            raise ParseError(f"turns must be float32 or float16 ({len(poses)}, {len(bones)}, 4), "
                             f"got {turns.dtype} {turns.shape}", path)
        turns = turns.astype(np.float32, copy=False)
        norm = np.linalg.norm(turns, axis=2)
        if not (np.isfinite(norm).all() and np.abs(norm - 1).max(initial=0) < 0.01):
            raise ParseError("turns must be unit quaternions", path)
    return KnowledgeBase(poses, tuple(names), fps, limbs, tuple(sources), index, tuple(bones),
                         turns)


def motion_files(sources, exclude=()):
    """Motion files under the given files/folders, sorted, minus those matching ``exclude``."""
    files = []
    for src in map(Path, sources):
        if src.is_dir():
            files.extend(p for p in sorted(src.rglob("*"))
                         if p.is_file() and p.name.lower().endswith(READ_FORMATS))
        elif src.is_file():
            files.append(src)
        else:
            raise GapFillError(f"no such file or folder: {src}")
    keep = [f for f in files if not any(fnmatch.fnmatch(str(f), g) or fnmatch.fnmatch(f.name, g)
                                        for g in exclude)]
    return keep


def resample(positions, fps_from, fps_to):
    """Resample (frames, points, 3) in time by linear interpolation (exact subsampling when the
    rates divide)."""
    if abs(fps_from - fps_to) < 1e-6:
        return positions
    ratio = fps_from / fps_to
    if abs(ratio - round(ratio)) < 1e-6:
        return positions[::int(round(ratio))]
    frames = positions.shape[0]
    t_new = np.arange(0, (frames - 1) / fps_from + 1e-9, 1 / fps_to) * fps_from
    lo = np.floor(t_new).astype(int).clip(0, frames - 1)
    hi = (lo + 1).clip(0, frames - 1)
    w = (t_new - lo)[:, None, None]
    return positions[lo] * (1 - w) + positions[hi] * w


def build_kb(sources, fps=None, exclude=(), skip_frames=0, stride=1, read_options=None,
             progress=None, should_cancel=None, report=None):
    """Build a :class:`KnowledgeBase` from motion files or folders.

    Parameters
    ----------
    sources : list of path
        Files and folders (searched recursively for readable motion files).
    fps : float, optional
        Resample every source to this rate (default: the first source's).
    exclude : list of str
        Glob patterns of paths or file names to leave out (e.g. the test trial's subject).
    skip_frames : int
        Leading frames dropped from every file (BVH reference poses).
    stride : int
        Keep every ``stride``-th pose after resampling (poses at 120 fps are very redundant);
        the knowledge base's rate is ``fps / stride``.
    progress, should_cancel, report : callables, optional
        ``progress(fraction, message)``, ``should_cancel() -> bool``, ``report(message)``.

    Only points present in every source are kept; frames with any of them missing are dropped.
    """
    files = motion_files(sources, exclude)
    if not files:
        raise GapFillError("no motion files in the knowledge-base sources")
    # armature takes (BVH, ASF/AMC: rest pose = the ASF's zero pose) also give their bones'
    # rotations (all of them, or none: one KB, one kind)
    rigs = all(file_suffix(path) in RIG_FORMATS for path in files)
    asf = (read_options or {}).get("asf")
    motions, turns = [], []
    for i, path in enumerate(files):
        if should_cancel and should_cancel():
            raise KeyboardInterrupt
        if progress:
            progress(i / len(files), f"reading {path.name}")
        # an armature take's file is parsed once for its joints and its bones' rotations
        bvh = parse_bvh(path) if rigs and file_suffix(path) in BVH_FORMATS else None
        motion = read_motion(path, skip_frames=skip_frames, bvh=bvh, **(read_options or {}))
        warning = upright_warning(motion)
        if warning and report:
            report(f"{path.name}: {warning}")
        motions.append(motion)
        if rigs:
            turns.append(take_turns(path, skip_frames, motion.n_frames, asf, bvh))
            rigs = turns[-1] is not None
    kb = kb_from_motions(motions, fps, stride, report, turns if rigs else None)
    if progress:
        progress(1.0, "done")
    return kb


def take_turns(path, skip_frames, n_frames, asf=None, bvh=None):
    """:func:`rig_turns` of an armature take file (``bvh``: a BVH's, already parsed); None
    where the armature's frames are not the motion's."""
    rig, basis, _ = read_rig_basis(path, skip_frames, asf, bvh)
    if len(basis) != n_frames:
        return None
    return rig_turns(rig, basis)


def motion_turns(motion):
    """:func:`rig_turns` of the armature the add-on's skeleton import builds for a skeleton
    motion (:func:`~.rig.rig_from_motion`): what :func:`kb_from_motions` keeps of such takes."""
    from .rig import basis_matrices, rig_from_motion

    rig, channels, location = rig_from_motion(motion)
    return rig_turns(rig, basis_matrices(rig, channels, location))


def rig_turns(rig, basis):
    """``(bone names, quaternions (frames, bones, 4))``: an armature's bone rotations as a
    knowledge base keeps them (:func:`~.rig.aligned_turns`, signs continuous in time)."""
    from scipy.spatial.transform import Rotation

    from .rig import aligned_turns

    turns = aligned_turns(rig, basis)
    quat = Rotation.from_matrix(turns.reshape(-1, 3, 3)).as_quat().reshape(turns.shape[:2] + (4,))
    flip = np.ones(quat.shape[:2])
    flip[1:] = np.where(np.sum(quat[1:] * quat[:-1], axis=2) < 0, -1.0, 1.0)
    return tuple(rig.names), quat * np.cumprod(flip, axis=0)[..., None]


def kb_from_motions(motions, fps=None, stride=1, report=None, turns=None):
    """Build a :class:`KnowledgeBase` from :class:`Motion` objects (see :func:`build_kb`).

    Only points present in every motion are kept; frames with any of them missing are dropped.
    ``turns``: per motion ``(bone names, quaternions (frames, bones, 4))`` of
    :func:`take_turns`, kept for the bones every motion has.
    """
    report = report or (lambda message: None)
    if not motions:
        raise GapFillError("no motions for the knowledge base")
    names = [n for n in motions[0].names if all(n in m.names for m in motions[1:])]
    dropped = sorted({n for m in motions for n in m.names} - set(names))
    if dropped:
        report(f"points not in every source, left out of the knowledge base: {', '.join(dropped)}")
    if len(names) < 3:
        raise GapFillError("the sources share fewer than 3 point names: they are different "
                           "skeletons or marker sets")
    reference = find_reference(names)
    fps = float(fps or motions[0].fps)
    bones = () if turns is None else tuple(
        b for b in turns[0][0] if all(b in t[0] for t in turns[1:]))
    poses, index, kept_turns = [], [], []
    for i, motion in enumerate(motions):
        sub = motion.select(names)
        pos = resample(sub.positions, motion.fps, fps)[::max(1, int(stride))]
        complete = ~np.isnan(pos).any(axis=(1, 2))
        pos = pos[complete]
        if not len(pos):
            report(f"{motion.source or f'motion {i}'}: no complete frame, skipped")
            continue
        root, angle = frames_of(pos, reference)
        poses.append(normalize(pos, root, angle).astype(np.float32))
        index.append(np.full(len(pos), i, dtype=np.int32))
        if bones:
            own, quat = turns[i]
            quat = resample(quat[:, [own.index(b) for b in bones]], motion.fps, fps)
            quat = quat[::max(1, int(stride))][complete]
            kept_turns.append((quat / np.linalg.norm(quat, axis=2, keepdims=True))
                              .astype(np.float32))
    if not poses:
        raise GapFillError("no complete poses in the knowledge-base sources")
    limbs = motions[0].select(names).limbs
    # consecutive poses of a source lie 1 / fps apart: a stride lowers the rate
    return KnowledgeBase(np.concatenate(poses), tuple(names), fps / max(1, int(stride)), limbs,
                         tuple(str(m.source or f"motion {i}") for i, m in enumerate(motions)),
                         np.concatenate(index), bones,
                         np.concatenate(kept_turns) if bones else None)


def match_names(kb, names):
    """Indices into ``kb.names`` for the query ``names`` that the KB has, and those it lacks.

    Raises :class:`GapFillError` when the two share too few points to be the same skeleton or
    marker set, naming what is missing.
    """
    index = {n: i for i, n in enumerate(kb.names)}
    common = [n for n in names if n in index]
    lacking = [n for n in names if n not in index]
    if len(common) < max(3, len(names) // 2):
        raise GapFillError(
            f"the knowledge base does not match this motion: it lacks {len(lacking)} of its "
            f"{len(names)} points ({', '.join(lacking[:10])}{'...' if len(lacking) > 10 else ''}); "
            f"it holds {', '.join(kb.names[:10])}{'...' if len(kb.names) > 10 else ''}")
    return common, lacking


#: knowledge bases shipped with the extension, built from CMU motion by
#: tools/build_starter_kbs.py: the Daz-friendly BVH skeleton (43 joints), the 41-marker set and
#: the CMU ASF skeleton (31 joints)
STARTER_DIR = Path(__file__).resolve().parents[1] / "sample_scenes"
STARTER_KBS = ("cmu_daz43_kb.npz", "cmu_markers41_kb.npz", "cmu_asf31_kb.npz")


_STARTERS = {}


def starter_kb(names):
    """``(path, kb)``: the starter knowledge base that shares the most of ``names`` and enough of
    them to fill (:func:`match_names`); :class:`GapFillError` naming what the closest lacks
    when none does."""
    best, error = None, None
    for path in (STARTER_DIR / name for name in STARTER_KBS):
        if not path.is_file():
            continue
        if path not in _STARTERS:  # loaded once per process (a batch asks per take)
            _STARTERS[path] = load_kb(path)
        kb = _STARTERS[path]
        try:
            common, _ = match_names(kb, names)
        except GapFillError as exc:
            error = error or exc
            continue
        if best is None or len(common) > best[0]:
            best = (len(common), path, kb)
    if best is None:
        raise GapFillError("no starter knowledge base fits this take: "
                           + (str(error).replace("the knowledge base", "the closest")
                              if error else f"none found in {STARTER_DIR}")
                           + "; build one with 'kb build' from clean takes of this set")
    return best[1], best[2]


__all__ = ["KnowledgeBase", "build_kb", "kb_from_motions", "load_kb", "match_names", "resample",
           "starter_kb"]
