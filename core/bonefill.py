"""Armature gaps are rotation gaps: fill the missing rotations of bones, keep every other key.

A bone without keys over some frames has an unknown rotation there (and an unknown location where
its location is animated); every other bone keeps its keyed channels, so the joints below a
gapped bone ride along rigidly with it. What the animator sees across such a gap is the
F-curve interpolation of the keys either side (``interp``): free and often good. Every method
starts from the keys and changes only the gapped bones' rotations (and locations) on the gap
frames:

- ``bezier`` (a baseline: one click in the Graph Editor, Key > Interpolation Mode > Bezier):
  the curve Blender draws across the gap once the keys are Bezier, with the handles and
  smoothing it gives new keys by default (:func:`~.rig.bezier_channels`);
- ``hermite`` (a baseline: a cubic on Blender's F-curves): each channel a cubic from the key
  before the gap to the key after it, leaving and arriving with the velocities the keys show
  (damped on gaps over ``hermite_seconds``); closer to the motion on short gaps than
  ``bezier``, whose handles level out at every turn of a curve (docs/EVALUATION.md).
  The fills of the project's own (``auto``'s candidates, ``knn``'s start) take the same cubic
  on the rotations instead of their Euler channels, which race near gimbal lock
  (:func:`~.rig.hermite_rotations`);
- ``match``: motion matching in rotation space (:func:`~.matching.match_windows`): the
  knowledge-base windows of consecutive poses whose bone rotations move most like the take's
  over the gap and half a second either side (where the gapped bones are keyed too), matched
  in overlapping pieces of 0.5 s (1 s where several bones are gapped together) at a few
  playback speeds; each gapped bone takes the windows' mean rotation, times an offset slerped
  across the gap from what meets the keys at either end. Needs a knowledge base built from
  armature takes of the same skeleton (``KnowledgeBase.turns``). The take itself is searched
  too, wherever it keys the bones a stretch lacks;
- ``regress``: what the rest of the body says of the bone: a ridge regression of its channels on
  the channels of the bones keyed throughout the gap (their motion a tenth of a second either
  side too), fitted on the frames within two seconds of the gap where the take keys them all
  (:func:`~.rig.regress_channels`); the same subject, the same moment of the take, no knowledge
  base;
- ``learn``: the take's own interpolator (:func:`~.rig.learned_rotations`): each gap frame a
  turn off the slerp between the keys, linear in the path between them and the steps to four
  keys beyond each, with the weights that fill every other window of the gap's length where
  the take keys the bone best (least squares): between the slerp and a cubic, whichever the
  bone's motion calls for; then what that misses, as the bones within two joints of it keyed
  throughout the gap miss their own such fits there (a 3 x 3 ridge regression per bone,
  fitted on the same windows): the body's motion over the gap, no knowledge base;
- ``knn``: the knowledge base's joint positions near ``hermite``: the local models of
  :mod:`.recover`, fitted to the K nearest poses over every joint, pull the joints the gaps
  move towards likely poses, the more the further a frame lies from a key
  (:func:`~.models.soft_poses`, the take's own complete poses added to the KB); then,
  top-down, each gapped bone takes the rotation that best carries its rigid subtree - its
  descendants posed by their own keys - onto those joints (:func:`carry_subtrees`);
- ``auto`` (the default): per gap ``match``, ``mix`` (a quarter of the way from ``hermite`` to
  ``match``), ``stack`` (``interp``, ``hermite``, ``match`` and ``regress`` weighed together
  frame by frame, by the frame's distance from the keys: :mod:`.stacking`, the weights that
  refill the take's copies best), on gaps under ``learn_seconds`` (0.4 s) also ``learn``, or
  ``interp``, as copies of the gap - same bone, same length,
  placed where the bone is keyed - refilled by each say (:meth:`_Job.auto`); gaps of
  ``long_stack`` seconds or more that none of them improves take ``stack_long`` (the stack with
  ``regress`` on the pose alone and ``regress`` with a Gaussian kernel beside; in equal parts
  in a take too short for copies, where other bones' gaps overlap the gap), and so do gaps of
  ``few_copies`` seconds or more that fewer than ``auto_copies`` copies of their own fit
  beside; every gap of ``long_stack`` seconds or more that does not keep ``interp`` then goes
  halfway on to the mean of ``match`` and ``regress_kernel`` (``consensus``: three estimates
  from different evidence, averaged); the shorter gaps go from ``interp`` towards their fill
  only as far as the fills agree on the gap, and as far as it departs from ``interp`` beyond
  the error its copies expect of it (``auto_wary``), and the part of the interpolation such a
  gap keeps goes half way on to the mean of two stacked fills that agree on it (``corroborate``:
  two estimates from different evidence bearing each other out; on a gap ``learn`` is judged on,
  ``learn`` may be one of them, and then ``corroborate_learn`` of the way); a gap of 0.4 s up to
  ``mid_learn_seconds`` (0.6 s) with keys beyond its keys then goes ``mid_learn`` (a fifth) of
  the way on to ``learn``, too long to be judged by the copies there; in a take too short for
  copies, a long gap keeps ``interp`` where it and ``regress`` agree far more closely than
  either does with ``match``, and takes the mean of ``match`` and ``regress_kernel`` where
  ``match`` would fill it unjudged (``unjudged_consensus``); a gap at a clip end (one key,
  which Blender holds) goes on to the mean of ``match`` and ``regress_kernel`` where the two
  agree on it (``ends_share``: all the way);
  with a knowledge base of positions only, ``knn``, ``half`` (half-way from ``interp`` to
  ``knn``) and ``recall`` (subtrees carried onto the knowledge base's guess from the known
  joints alone: a KB that holds the motion) stand in; without a knowledge base (a rig no
  starter one fits) it chooses the same way from the take's own fills - ``hermite``,
  ``regress``, ``regress_kernel`` and their stacks with ``interp`` - and its long gaps go
  halfway on to ``regress_kernel``; in a take too short for copies, short gaps take
  ``hermite`` and long ones go halfway from ``interp`` to ``regress_kernel``;
- ``slerp``: quaternion slerp between the rotations at the keys either side;
- ``positions``: the position-space fill of every joint below a gap, then each gapped bone turned
  to its children's filled joints (what the add-on did before; kept for comparison).

Root bones are never handed to the knowledge base (it holds poses about the root, not where the
body goes): ``knn`` and ``auto`` give their gaps ``hermite``'s curve (``knn``) or leave them to
the interpolation (``auto`` decides per gap like any other).
"""

from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .errors import GapFillError
from .kb import match_names
from .motion import Motion, blend_into_gaps, gap_runs, skeleton_limbs, widened
from .posing import best_rotation, child_handles, forward, gram_schmidt, order_bones, \
    rotation_between, solve_pose, tail_handles
from .rig import aligned_turns, basis_matrices, basis_turns, bezier_channels, \
    hermite_channels, hermite_rotations, interpolate_channels, learn_losses, learnable_runs, \
    learned_rotations, regress_channels
from . import stacking

BONE_METHODS = ("auto", "knn", "match", "regress", "learn", "interp", "bezier", "hermite",
                "slerp", "positions")
#: the methods that are not the project's own (``interp`` and ``bezier`` are Blender's own
#: curves through LINEAR and Bezier keys)
BONE_BASELINES = ("interp", "bezier", "hermite", "slerp")
#: every candidate a gap can take (``half``: half-way from ``interp`` to ``knn``; ``recall``:
#: the subtree carried onto the knowledge base's guess from the known joints alone; ``mix``:
#: ``mix_share`` of the way from ``hermite`` to ``match``)
CANDIDATES = ("interp", "hermite", "learn", "knn", "half", "recall", "match", "mix", "regress",
              "regress_pose", "regress_kernel")
#: what ``auto`` chooses from beside ``interp``: with a knowledge base of bone rotations, and
#: without one (built from positions alone, or by an older version)
AUTO_CANDIDATES = ("match", "mix", "learn")
AUTO_POSITIONS = ("knn", "half", "recall")
#: the fills ``auto``'s ``stack`` weighs together frame by frame where the knowledge base holds
#: bone rotations and the take has copies of its gaps (``stack_ridge``)
STACK_FILLS = ("interp", "hermite", "match", "regress")
LONG_STACK_FILLS = STACK_FILLS + ("regress_pose", "regress_kernel")
CONSENSUS_FILLS = ("match", "regress_kernel")
#: the methods that take a knowledge base, and those that cannot fill without one (``auto``
#: fills from the take alone: :data:`TAKE_ALONE_CANDIDATES`)
USES_KB = ("auto", "knn", "match", "positions")
NEEDS_KB = ("knn", "match", "positions")
#: the candidates that come from a knowledge base
KB_FILLS = ("knn", "half", "recall", "match", "mix")
#: what ``auto`` chooses from beside ``interp`` without a knowledge base (a rig no starter one
#: fits, none chosen): the take's own fills, stacked as :data:`STACK_FILLS` and
#: :data:`LONG_STACK_FILLS` are without those of :data:`KB_FILLS` (chosen on non-test takes,
#: docs/DESIGN.md)
TAKE_ALONE_CANDIDATES = ("hermite", "regress", "regress_kernel", "learn")
TAKE_ALONE_CONSENSUS = ("regress_kernel",)
TAKE_ALONE = ("auto fills from the take alone (its own regression, a cubic and Blender's "
              "interpolation, judged on copies of the gaps)")


@dataclass(frozen=True)
class BoneConfig:
    """What ``auto`` (and the fills it weighs) of the rotation fill go by; ``fill_bones(...,
    config=BoneConfig(...))``. The defaults were chosen on takes that are not test takes."""

    #: ``auto`` judges ``learn`` only on gaps shorter than this (seconds) with keys either side (the
    #: bone's own interpolator gains on gaps of 0.125-0.25 s and loses from 0.5 s on the non-test
    #: takes; at a clip's end it holds the key; docs/DESIGN.md)
    learn_seconds: float = 0.4
    #: the part of such a gap that ``auto`` keeps of the interpolation goes this share of the way on
    #: to ``learn`` where the bone's own windows of the gap's length say that ``learn`` loses (by 10
    #: % + 2 mm) no more than ``learn_trust`` of them (hundreds per bone where the three copies of a
    #: gap are a noisy judge; docs/DESIGN.md)
    learn_pull: float = 0.25
    learn_trust: float = 0.03
    #: how far ``mix`` goes from ``hermite`` towards ``match`` (tuned, docs/DESIGN.md)
    mix_share: float = 0.25
    stack_ridge: float = 0.3
    #: gaps of this many seconds or more for which no candidate passes on the copies take
    #: ``stack_long`` rather than ``interp``: :data:`LONG_STACK_FILLS` weighed together like
    #: ``stack`` (``regress_pose``: ``regress`` on the other bones' pose at the frame alone;
    #: ``regress_kernel``: ``regress`` with a Gaussian kernel beside the linear one); in a take
    #: without copies, those of its long gaps that other bones' gaps overlap, in equal parts (tuned,
    #: docs/DESIGN.md)
    long_stack: float = 0.75
    #: a gap of ``long_stack`` seconds or more that does not keep the interpolation goes this share
    #: of the way from its fill to the mean of :data:`CONSENSUS_FILLS`: the knowledge base's motion
    #: and the take's own regression, estimates that owe each other and the copies' choice little
    #: (chosen on non-test takes, docs/DESIGN.md)
    consensus: float = 0.5
    #: a gap at a clip's end (one key: Blender holds it) where those two agree - lie apart by less
    #: than ``corroborated`` times their mean departure from the held key (RMS over the joints the
    #: bone moves) - goes this share of the way on from its fill (and its consensus) to their mean:
    #: its copies, with keys at both ends, judge its fills against an interpolation far stronger
    #: than the held key, and two estimates from different evidence that bear each other out say
    #: what the key lacks (:meth:`_Job._ends_agreed`; chosen by leave-one-subject-out on non-test
    #: takes, docs/DESIGN.md)
    ends_share: float = 1.0
    #: last, each gap with keys at both ends takes, of its fill and these (each filling the take's
    #: gaps alone), the one that lies nearest the others (the least summed RMS distance over the
    #: joints its bone moves): fills from different evidence fail on different gaps, and the one the
    #: others bear out is the one least likely to have failed (:meth:`_Job._medoid`; chosen on
    #: non-test takes, docs/DESIGN.md), in a take with copies of its gaps
    medoid_fills: tuple = ("match", "regress", "learn")
    #: in a take with copies, a gap from ``learn_seconds`` up to ``mid_learn_seconds`` with keys
    #: beyond its keys (too long for ``learn`` to be judged) goes this share of the way on from its
    #: fill to ``learn``, the bone's own interpolator: alone it carries the keys' motion too far at
    #: that length, a part of it steadies whatever the copies chose (chosen on non-test takes,
    #: docs/DESIGN.md: at 0.67 s it lost gaps, at 1 s it did not pay)
    mid_learn: float = 0.2
    mid_learn_seconds: float = 0.6
    #: where the take has copies, every gap shorter than ``long_stack`` goes from ``interp`` towards
    #: the chosen fill only as far as the stacked fills agree on the gap (:meth:`_Job._doubted`):
    #: the weight of their spread against the departure from ``interp`` (tuned, docs/DESIGN.md;
    #: ``stack_long`` goes undoubted)
    auto_doubt: float = 0.1
    #: and then only as far as its departure from ``interp`` stands out of the fill's own error on
    #: the gap's copies: the share is cut by ``max(0, 1 - auto_wary * E / A)``, ``E`` the fill's
    #: mean squared joint error expected from the copies, ``A`` the gap's squared departure (a
    #: shrinkage towards the interpolation; chosen on non-test takes, docs/DESIGN.md)
    auto_wary: float = 0.1
    #: then the part of the interpolation such a gap keeps (``1 - share``) goes this share of the
    #: way on to the mean of the two stacked fills (those of :data:`STACK_FILLS` but ``interp``)
    #: that agree on the gap - lie apart by less than ``corroborated`` times their mean departure
    #: from the interpolation, the closest such pair: two estimates from different evidence (the
    #: keys' motion, the rest of the body, the knowledge base) that bear each other out
    #: (:meth:`_Job._corroborated`; chosen on non-test takes, docs/DESIGN.md)
    corroborate: float = 0.5
    corroborated: float = 0.45
    #: on a gap where ``learn`` is judged (under ``learn_seconds``, keys beyond its keys), ``learn``
    #: - how the bone's own motion and the bones about it go on over the gap - may be one of that
    #: pair; a pair with it moves the kept part this share of the way instead (half of the way lost
    #: gaps on the held-back takes; chosen on non-test takes, docs/DESIGN.md)
    corroborate_learn: float = 0.42
    #: and where the take's copies, all of them together, favour the cubic (``hermite``) over the
    #: interpolation - their mean log ratio of its squared joint error to the interpolation's lies
    #: below ``-cubic_trust`` - the part such a gap kept goes ``min(cubic_pull, -mean -
    #: cubic_trust)`` of the way on to the cubic: a gap's own few copies judge it against the bar of
    #: ``promote_short``, the take's hundreds tell whether its motion suits the cubic at all (chosen
    #: on non-test takes, docs/DESIGN.md)
    cubic_trust: float = 0.5
    cubic_pull: float = 0.5
    #: ``regress``: the other bones' channels this many seconds either side count too; fitted within
    #: this many seconds of the gap, with this ridge penalty per frame (tuned, docs/DESIGN.md)
    regress_lags: tuple = (0.05, 0.1)
    regress_window: float = 3.0
    regress_ridge: float = 0.1
    #: in a take too short for copies, without a knowledge base, a gap of ``long_gap`` seconds or
    #: more goes this share of the way from ``interp`` to ``regress_kernel`` (a shorter one takes
    #: ``hermite``): unjudged, so part of the way (chosen on 1.5 s cuts of non-test takes,
    #: docs/DESIGN.md)
    take_alone_unjudged: float = 0.5
    #: ``auto`` takes a candidate for a gap where its error on the gap's copies is below this share
    #: of interpolation's (the better candidate where both are), on gaps of ``long_gap`` seconds or
    #: more and on shorter ones, where interpolation is hard to beat: part of the way there below
    #: ``promote_short``, all the way only below ``promote_short_whole`` (tuned on non-test
    #: subjects, docs/DESIGN.md)
    promote: float = 0.9
    promote_short: float = 0.7
    promote_short_whole: float = 0.3
    #: weight (in copies) of the take's mean over all copies in each gap's score
    shrink: float = 1.0
    #: how far ``auto`` may go from ``interp`` towards the chosen candidate: per gap the share whose
    #: blend refills the gap's copies best
    auto_shares: tuple = (0.25, 0.5, 0.75, 1.0)
    #: gaps of this many seconds or more are long (above)
    long_gap: float = 0.5
    #: in a take without copies, a long gap that ``match`` fills unjudged goes this share of the way
    #: on to the mean of :data:`CONSENSUS_FILLS` (1: the mean itself; chosen on non-test takes,
    #: docs/DESIGN.md)
    unjudged_consensus: float = 1.0
    #: in a take without copies, a long gap keeps the interpolation where it and ``regress`` lie
    #: within this share of ``match``'s distance from the nearer of them (RMS over the joints the
    #: gap moves; :meth:`_Job._outvoted`; chosen on non-test takes, docs/DESIGN.md)
    outvoted: float = 0.5
    #: copies of each gap ``auto`` refills, and the frames kept between a copy and any gap
    auto_copies: int = 3
    #: a gap of this many seconds or more that fewer than ``auto_copies`` copies of its own fit
    #: takes ``stack_long``: the take's other copies do not speak for it (chosen on non-test takes,
    #: docs/DESIGN.md)
    few_copies: float = 1.5
    copy_margin: int = 10
    #: ``hermite`` carries the velocities at a gap's ends as if the gap lasted at most this long
    hermite_seconds: float = 0.5
    #: ``learn``, the take's own interpolator (:func:`~.rig.learned_rotations`): keys beyond each
    #: gap's keys it reads, and its ridge (none: the bone's own windows, hundreds of them, pin its
    #: few weights; docs/DESIGN.md)
    learn_keys: int = 4
    learn_ridge: float = 0.0
    #: ``learn``'s bones that tell of a gapped one: those within this many joints of it; the ridges
    #: (shares of the mean diagonal) of what their own fits miss, the one that predicts each half of
    #: the take's windows best from the other (docs/DESIGN.md)
    learn_hops: int = 2
    learn_body_ridges: tuple = (0.1, 0.3, 1.0)
    #: how fast (m/s) the interpolation of a gap is taken to drift from the truth, per second to the
    #: nearest key: how far ``knn`` lets the knowledge base move a joint (tuned, docs/DESIGN.md)
    guess_speed: float = 0.1
    #: weight of the current (interpolated) rotation in each gapped bone's fit, as a share of the
    #: fitted joints' spread about the bone's head (pseudo-points; tuned, docs/DESIGN.md)
    stay: float = 0.5
    #: seconds of context either side of a gap that ``match`` compares, and how much the gapped
    #: bones count there against any other bone
    match_context: float = 0.5
    match_context_weight: float = 4.0
    #: seconds of the pieces ``match`` matches a stretch in, where one bone is gapped there and
    #: where several are (tuned, docs/DESIGN.md)
    match_piece: float = 0.5
    match_piece_many: float = 1.0
    match_own: bool = True
    match_damp: bool = True
    #: the windows' mean leans to a window that stands out (:func:`~.matching.match_windows`'
    #: ``lean``; docs/DESIGN.md)
    match_lean: bool = True


@dataclass(frozen=True)
class GapChoice:
    """How one gap of a bone was filled (``fill_bones(..., return_choices=True)``).

    ``bone``: its name; ``first``, ``last``: its frames (rows of the take, inclusive);
    ``method``: the fill it took (``interp``: Blender's interpolation kept); ``share``: how far
    from the interpolation towards that fill (1: all the way, 0: the interpolation);
    ``estimate``: ``auto``'s judgement, the RMS joint error of that fill (at the share the
    copies chose, before any consensus) on copies of the gap - the same bone and length,
    placed where the bone is keyed - as a share of the interpolation's there (their geometric
    mean, drawn towards the take's mean over all copies as ``auto`` scores them); NaN where no
    copies judged the gap; ``consensus``: how far the fill then went on towards the mean of
    the fills named in ``towards`` (0: not at all; :data:`CONSENSUS_FILLS`, without a
    knowledge base :data:`TAKE_ALONE_CONSENSUS`, joined by " + "; at a clip end where those two
    agree, ``ends_share`` of the rest of the way too); ``corroborated``: the two
    fills (joined by " + ") whose mean the part of a short gap kept of the interpolation went
    ``corroborate`` (with ``learn``: ``corroborate_learn``) of the way on to, where
    they agree on the gap ("": none); ``cubic``: how
    far the gap went towards the cubic (``hermite``) beside, where the take's copies favour it
    (``cubic_trust``; 0: not at all); ``learnt``: how far it went towards ``learn``
    beside, where the bone's own windows trust it (``learn_trust``; 0: not at all);
    ``medoid``: the fill of ``medoid_fills`` that then took the gap's place, lying nearer
    the other fills than all that went before ("": none did)."""

    bone: str
    first: int
    last: int
    method: str
    share: float
    estimate: float = float("nan")
    consensus: float = 0.0
    towards: str = ""
    corroborated: str = ""
    cubic: float = 0.0
    learnt: float = 0.0
    medoid: str = ""


def fill_bones(rig, channels, location, gaps, fps, kb=None, method="auto", moves=None,
               to_metres=None, settings=None, progress=None, should_cancel=None, report=None,
               return_choices=False, trace=None, config=None):
    """Fill the rotation gaps of an armature take.

    Parameters
    ----------
    rig : Rig
    channels : ndarray, shape (frames, bones, 4)
        Rotation channels as the animator sees them: keyed values, and across each gap what
        the F-curves show (their interpolation of the keys either side).
    location : ndarray, shape (frames, bones, 3)
        Location channels, likewise.
    gaps : ndarray, shape (frames, bones), bool
        Frames where a bone has no keys: its rotation is unknown, and its location where the
        bone moves (``moves``).
    fps : float
    kb : KnowledgeBase, optional
        Needed by ``knn``, ``match`` and ``positions``; ``auto`` without one fills from the
        take alone. Joint names = bone names.
    method : str
        One of :data:`BONE_METHODS`.
    moves : ndarray, shape (bones,), bool, optional
        Bones whose location is animated (default: roots).
    to_metres : ndarray, shape (4, 4), optional
        Armature space -> world metres, Z up (default: identity).
    settings, config : KnnSettings, BoneConfig, optional
    report, trace : callable, optional
        What the user is told; what each of ``auto``'s stages did (``--verbose``).
    return_choices : bool
        Also return how each gap was filled (:mod:`.explain` says it in words).

    Returns
    -------
    ndarray, shape (frames, bones, 4, 4)
        Basis matrices: the input's everywhere except the gapped bones on their gap frames.
    list of GapChoice
        With ``return_choices``: per gap (run of gap frames of a bone, bone-major order) the
        fill it took; ``auto`` decides per gap, every other method takes its own.
    """
    if method not in BONE_METHODS:
        raise GapFillError(f"unknown method {method!r}; choose from {', '.join(BONE_METHODS)}")
    if method in NEEDS_KB and kb is None:
        raise GapFillError(f"method {method!r} needs a knowledge base; without one, 'auto' "
                           "fills from the take alone")
    if method in USES_KB and kb is not None:  # another skeleton's: a clear error now
        lacking = match_names(kb, rig.names)[1]
        if lacking and report:
            report("not in the knowledge base, left to the fills that need none (the cubic, the "
                   f"take's own regression, Blender's interpolation): {', '.join(lacking)}")
    if method == "match" and kb.turns is None:
        raise GapFillError("method 'match' needs a knowledge base with bone rotations: build it "
                           "with 'kb build' from BVH or ASF/AMC takes of this skeleton")
    gaps = np.asarray(gaps, dtype=bool)
    if gaps.shape != channels.shape[:2]:
        raise GapFillError(f"gaps have shape {gaps.shape}, the take {channels.shape[:2]}")
    moves = rig.roots if moves is None else np.asarray(moves, dtype=bool)
    job = _Job(rig, fps, kb, moves, np.eye(4) if to_metres is None else np.asarray(to_metres),
               settings, progress or (lambda fraction, message: None), should_cancel,
               report or (lambda message: None), trace, config)
    seen = basis_matrices(rig, channels, location)
    if method == "interp" or not gaps.any():
        basis = seen
    elif method == "slerp":
        basis = _slerp(seen, gaps, moves)
    elif method == "bezier":
        basis = basis_matrices(rig, bezier_channels(channels, gaps),
                               bezier_channels(location, gaps & moves), seen, gaps.any(axis=0))
    elif method == "hermite":
        basis = job.hermite(channels, location, gaps, seen, on_channels=True)
    elif method == "regress":
        basis = job.regress(channels, location, gaps, seen)
    elif method == "learn":
        basis = job.learn(gaps, seen)
    elif method == "positions":
        basis = job.positions(seen, job.for_kb(gaps))
    elif method == "knn":
        basis = job.knn(job.hermite(channels, location, gaps, seen), job.for_kb(gaps))
    elif method == "match":
        basis = job.match(seen, job.for_kb(gaps))
    else:
        basis = job.auto(channels, location, gaps, seen)
    if not return_choices:
        return basis
    runs = gap_runs(gaps)  # auto's choices are per gap; every other method takes its own
    choices = job.choices or [(method, 0.0 if method == "interp" else 1.0)] * len(runs)
    estimates = job.estimates or [float("nan")] * len(runs)
    consensus = job.consensus or [0.0] * len(runs)
    corroborated = job.corroborated or [None] * len(runs)
    cubic = job.cubic or [0.0] * len(runs)
    learnt = job.learnt or [0.0] * len(runs)
    towards = job.towards or [()] * len(runs)
    medoids = job.medoids or [""] * len(runs)
    return basis, [GapChoice(rig.names[b], a, e, name, float(share), float(estimate), further,
                             " + ".join(onto) if further else "", " + ".join(pair or ()),
                             float(pulled), float(learn), medoid)
                   for (b, a, e), (name, share), estimate, further, onto, pair, pulled, learn,
                   medoid in zip(runs, choices, estimates, consensus, towards, corroborated,
                                 cubic, learnt, medoids)]


class _Job:
    """One fill: the rig, the knowledge base and the callbacks its steps share."""

    def __init__(self, rig, fps, kb, moves, to_metres, settings, progress, should_cancel,
                 report, trace=None, config=None):
        self.rig, self.fps, self.kb, self.moves = rig, fps, kb, moves
        self.cfg = config or BoneConfig()
        self.to_metres = to_metres
        self.settings = settings
        self.progress, self.should_cancel, self.report = progress, should_cancel, report
        self.trace = trace or (lambda message: None)  # what each stage of auto did (--verbose)
        self.below = rig.placed_by()
        self._kb_features = None  # the knowledge base's rotations as match's features
        # a moving bone places its own head (heads rigs; a tails rig's root joint is its head)
        self.own = moves & (rig.roots if rig.lengths is not None else True)
        # auto's choice per gap, its estimate of it from the copies and how far the gap then
        # went on to the long-gap consensus (None: not auto)
        self.choices = self.estimates = self.consensus = self.corroborated = self.cubic = None
        self.learnt = self.towards = self.medoids = None
        # the fills auto stacks, and those its long gaps go on to: without a knowledge base,
        # the take's own
        self.stack_fills, self.long_fills = (
            (STACK_FILLS, LONG_STACK_FILLS) if kb is not None else
            tuple(tuple(f for f in fills if f not in KB_FILLS)
                  for fills in (STACK_FILLS, LONG_STACK_FILLS)))
        self.consensus_fills = CONSENSUS_FILLS if kb is not None else TAKE_ALONE_CONSENSUS

    def moved_by(self, b):
        """(joints,) bool: the joints bone ``b`` moves (below it, and its own where it moves)."""
        return self.below[b] | (self.own & (np.arange(len(self.own)) == b))

    def short(self, a, e):
        """Whether a gap over frames ``a``-``e`` is shorter than ``long_stack`` seconds:
        ``auto`` doubts, corroborates and pulls such gaps; longer ones it stacks."""
        return e - a + 1 < self.cfg.long_stack * self.fps

    def unknown(self, gaps):
        """(frames, joints) joints the gaps leave unknown."""
        return (gaps.astype(np.int64) @ self.below.astype(np.int64) > 0) | (gaps & self.own)

    def metre_scale(self):
        """Metres per unit of the rig."""
        return float(np.cbrt(abs(np.linalg.det(self.to_metres[:3, :3]))))

    def world(self, basis):
        joints = self.rig.joints(basis)
        return joints @ self.to_metres[:3, :3].T + self.to_metres[:3, 3]

    def predict(self, basis, gaps):
        """The knowledge base's joints (frames, joints, 3) in armature space where the gaps
        leave them unknown, from nothing but the known joints (NaN where it cannot tell)."""
        from .recover import KnnSettings, fill_knn

        unknown = self.unknown(gaps)
        pos = np.where(unknown[..., None], np.nan, self.world(basis))
        motion = Motion(pos, self.rig.names, self.fps, parents=self.rig.parents,
                        limbs=skeleton_limbs(self.rig.parents))
        filled = fill_knn(motion, self.kb, self.settings or KnnSettings(),
                          progress=self.progress, should_cancel=self.should_cancel,
                          report=self.report).positions
        return self.armature(filled, unknown)

    def refine(self, basis, gaps):
        """The local models' most likely joints near what the F-curves show: each joint a gap
        leaves unknown is trusted to within ``guess_speed`` times its time to the nearest end of
        its gap (:func:`~.models.soft_poses`); armature space, NaN where known."""
        from .models import KnnSettings, soft_poses

        unknown = self.unknown(gaps)
        doubt = np.zeros(gaps.shape)
        for b, a, e in gap_runs(gaps):
            # from the nearer end, at a clip end too: measured from the one key, the models
            # pull its far frames further from the held key, and knn's clip ends lost (ASF/AMC
            # tuning takes 1.07 of this per take-setting, docs/DESIGN.md)
            away = stacking.from_keys(e - a + 1) / self.fps
            joints = self.moved_by(b)
            doubt[a:e + 1, joints] = np.maximum(doubt[a:e + 1, joints],
                                                self.cfg.guess_speed * away[:, None])
        # also model a frame either side of each gap: the model's offset from the keys there
        # is blended across the gap (its bias, not the shape it gives the gap)
        around = widened(unknown)
        seen = self.world(basis)
        model = soft_poses(seen, list(self.rig.names), doubt, self.with_take(seen, unknown),
                           self.fps, self.settings or KnnSettings(),
                           frames=np.flatnonzero(around.any(axis=1)),
                           should_cancel=self.should_cancel)
        world = blend_into_gaps(np.where(unknown[..., None], np.nan, seen), model, unknown,
                                around)
        return self.armature(world, unknown)

    def with_take(self, world, unknown):
        """The knowledge base plus the take's own poses where no joint is unknown: the same
        subject, the same style, the best neighbours where the take repeats itself."""
        from .kb import KnowledgeBase, kb_from_motions

        names = [n for n in self.kb.names if n in self.rig.names]
        cols = [self.rig.names.index(n) for n in names]
        keep = ~unknown[:, cols].any(axis=1)
        if keep.sum() < 2:
            return self.kb
        own = kb_from_motions([Motion(world[keep][:, cols], names, self.fps)])
        poses = np.full((own.size,) + self.kb.poses.shape[1:], np.nan, np.float32)
        poses[:, [self.kb.names.index(n) for n in names]] = own.poses
        if np.isnan(poses).any():
            return self.kb
        return KnowledgeBase(np.concatenate([self.kb.poses, poses]), self.kb.names, self.kb.fps,
                             self.kb.limbs, self.kb.sources + ("this take",),
                             np.concatenate([self.kb.source_index,
                                             np.full(own.size, len(self.kb.sources), np.int32)]))

    def armature(self, world, unknown):
        inverse = np.linalg.inv(self.to_metres)
        targets = world @ inverse[:3, :3].T + inverse[:3, 3]
        targets[~unknown] = np.nan
        return targets

    def knn(self, basis, gaps):
        """Gapped bones carried onto the local models' joints near ``basis``."""
        return carry_subtrees(self.rig, basis, gaps, self.refine(basis, gaps), self.moves,
                              self.below, self.cfg.stay)

    def match(self, basis, gaps):
        """Gapped bones turned as the knowledge-base windows that move most like the take around
        each gap (:func:`~.matching.match_windows`, in rotation space): the windows' mean
        rotation of each gapped bone, times an offset slerped across the gap from what it takes
        to meet the keys at either end. Needs a knowledge base with bone rotations; bones it
        lacks keep ``basis``."""
        cfg = self.cfg
        from .matching import match_windows, pose_table, take_as_source

        kb, rig = self.kb, self.rig
        bones = [b for b, name in enumerate(rig.names) if name in kb.bones and not rig.roots[b]]
        out = np.array(basis, dtype=float)
        gap = gaps[:, bones]
        if not gap.any():
            return out
        turns = aligned_turns(rig, basis)[:, bones]
        features = turns[..., :2].reshape(len(turns), len(bones), 6)
        if self._kb_features is None:  # once per fill: auto matches the copies, then the gaps
            kb_turns = kb.turns[:, [kb.bones.index(rig.names[b]) for b in bones]]
            # made unit here: scipy 1.16 (Blender 4.2-5.0's wheels) does it 10x slower, to
            # the same bits
            q = kb_turns.reshape(-1, 4).astype(float)
            q /= np.maximum(np.sqrt((q * q).sum(axis=1)), 1e-12)[:, None]
            kb_features = Rotation(q, normalize=False, copy=False).as_matrix()[
                ..., :2].reshape(len(kb_turns), len(bones), 6).astype(np.float32)
            self._kb_features = kb_features, pose_table(kb_features)
        kb_features, table = self._kb_features
        margin = int(round(cfg.match_context * self.fps))
        frames = len(gaps)
        busy = [(a, e) for _, a, e in gap_runs(gap.any(axis=1)[:, None])]
        stretches = [(max(0, a - margin), min(frames - 1, e + margin)) for a, e in busy]
        weight = np.where(gap, 0.0, 1.0)
        near = np.zeros_like(gap)
        for lo, hi in stretches:
            near[lo:hi + 1] = gap[lo:hi + 1].any(axis=0)
        weight[near & ~gap] = cfg.match_context_weight
        # the take itself wherever it keys the bones gapped in a stretch (not counting its
        # context; other gapped bones as Blender interpolates them): the same subject and style
        if cfg.match_own:
            own, source, hidden = take_as_source(features, gap, self.fps, kb.fps,
                                                 kb.source_index)
            kb_features = np.concatenate([kb_features, own])
            table = np.concatenate([table, pose_table(own)])
        else:
            source, hidden = kb.source_index, None
        # matched in pieces: short ones where one bone is gapped (the rest of the body says
        # much), longer ones where several are
        predicted, before = [None] * len(stretches), 0
        for width in (cfg.match_piece, cfg.match_piece_many):
            chosen = [i for i, (lo, hi) in enumerate(stretches)
                      if (gap[lo:hi + 1].any(axis=0).sum() == 1) == (width == cfg.match_piece)]

            def on_stretch(done, before=before):
                if self.should_cancel and self.should_cancel():
                    raise KeyboardInterrupt
                self.progress((before + done) / len(stretches), "matching the knowledge base")
            found = match_windows(features, weight, kb_features, source, self.fps, kb.fps,
                                  [stretches[i] for i in chosen], width=width,
                                  on_stretch=on_stretch, kb_hidden=hidden, table=table,
                                  lean=cfg.match_lean,
                                  needs=[gap[busy[i][0]:busy[i][1] + 1].any(axis=0)
                                         for i in chosen])
            before += len(chosen)
            for i, mean in zip(chosen, found):
                predicted[i] = mean
        for (first, last), (lo, hi), mean in zip(busy, stretches, predicted):
            if mean is None:
                continue
            pred = _orthonormal(mean)
            for i, a, e in gap_runs(gap[first:last + 1]):
                a, e = a + first, e + first
                ends = [t for t in (a - 1, e + 1) if lo <= t <= hi and not gap[t, i]]
                if not ends:
                    continue
                offsets = Rotation.from_matrix(
                    [turns[t, i] @ pred[t - lo, i].T for t in ends])
                span = np.arange(a, e + 1)
                shape = pred[a - lo:e - lo + 1, i]
                if len(ends) == 2:
                    offset = Slerp(ends, offsets)(span).as_matrix()
                    if cfg.match_damp:
                        shape = _damped(shape, pred[:, i], turns[lo:hi + 1, i],
                                        ~gap[lo:hi + 1, i], a - lo, e - lo)
                else:
                    offset = offsets.as_matrix()[[0] * len(span)]
                filled = offset @ shape
                out[a:e + 1, bones[i], :3, :3] = basis_turns(rig, filled, bones[i])
        return out

    def positions(self, basis, gaps):
        targets = self.predict(basis, gaps)
        targets = np.where(np.isnan(targets), self.rig.joints(basis), targets)
        handles = (child_handles(self.rig.rest, self.rig.parents) if self.rig.lengths is None
                   else tail_handles(self.rig.lengths, self.rig.parents))
        out, _ = solve_pose(self.rig.rest, self.rig.parents, basis, targets, gaps,
                            gaps & self.moves, handles)
        return out

    def for_kb(self, gaps):
        """The gaps the knowledge base can fill: not those of root bones (it holds poses about
        the root, not where the body is)."""
        roots = self.rig.roots
        if (gaps & roots).any():
            self.report("gaps of the root bone are interpolated (the knowledge base knows poses, "
                        "not where the body goes)")
        return gaps & ~roots

    def hermite(self, channels, location, gaps, base, on_channels=False):
        """``hermite``'s basis matrices; ``base``: those of ``channels`` and ``location``. The
        cubic turns the rotations (:func:`~.rig.hermite_rotations`); ``on_channels``: each
        rotation channel a cubic of its own, as a cubic on Blender's F-curves would do it
        (the baseline, which near gimbal lock swings a bone by radians)."""
        moving = gaps & self.moves
        damping = self.cfg.hermite_seconds * self.fps
        rotation = hermite_channels(channels, gaps, damping) if on_channels else channels
        out = basis_matrices(self.rig, rotation, hermite_channels(location, moving, damping),
                             base, gaps.any(axis=0))
        if not on_channels:
            out[..., :3, :3] = hermite_rotations(out[..., :3, :3], gaps, damping)
        return out

    def learn(self, gaps, base, fill=None):
        """``learn``'s basis matrices (``base``: those of the interpolation): each gapped
        rotation (of those in ``fill``, default all) as the bone's own motion goes on from the
        keys, and as the motion of the bones about it says (:func:`~.rig.learned_rotations`)."""
        out = np.array(base, dtype=float)
        cfg = self.cfg
        out[..., :3, :3] = learned_rotations(out[..., :3, :3], gaps, cfg.learn_keys,
                                             cfg.learn_ridge, self.rig.near(cfg.learn_hops),
                                             cfg.learn_body_ridges, fill=fill)
        return out

    def regress(self, channels, location, gaps, base, lags=None, kernel=False):
        """Each gapped bone (not a root) as the rest of the body says (``regress``, with the
        configured lags; with ``lags=()`` the body's pose at the frame alone, ``regress_pose``;
        with ``kernel``, ``regress_kernel``)."""
        cfg = self.cfg
        return basis_matrices(self.rig, regress_channels(
            channels, gaps, self.fps, cfg.regress_lags if lags is None else lags,
            cfg.regress_window, cfg.regress_ridge,
            fixed=self.rig.roots, kernel=kernel), location, base, gaps.any(axis=0))

    def candidates(self, channels, location, gaps, names, base, learn_on=None):
        """Basis matrices of the named candidates (of :data:`CANDIDATES`) for these gaps;
        ``base``: basis matrices that differ from the channels' only on the gapped bones;
        ``learn_on``: the gaps ``learn`` fits around (all the take's) and those it fills
        (default: ``gaps`` both)."""
        interp = basis_matrices(self.rig, channels, location, base, gaps.any(axis=0))
        out = {"interp": interp}
        if "learn" in names:
            unknown, fill = learn_on or (gaps, None)
            out["learn"] = self.learn(unknown, interp, fill)
        if "regress" in names:
            out["regress"] = self.regress(channels, location, gaps, interp)
        if "regress_pose" in names:
            out["regress_pose"] = self.regress(channels, location, gaps, interp, lags=())
        if "regress_kernel" in names:
            out["regress_kernel"] = self.regress(channels, location, gaps, interp, kernel=True)
        fillable = self.for_kb(gaps) if set(KB_FILLS) & set(names) else None
        if {"hermite", "knn", "half", "mix"} & set(names):
            out["hermite"] = self.hermite(channels, location, gaps, interp)
        if {"knn", "half"} & set(names):
            out["knn"] = self.knn(out["hermite"], fillable)
            out["half"] = halfway(out["interp"], out["knn"], gaps)
        if {"match", "mix"} & set(names) and self.kb is not None and self.kb.turns is not None:
            out["match"] = self.match(out["interp"], fillable)
            if "mix" in names:
                out["mix"] = halfway(out["hermite"], out["match"], gaps, self.cfg.mix_share)
        if "recall" in names:
            out["recall"] = carry_subtrees(self.rig, out["interp"], fillable,
                                           self.predict(out["interp"], fillable), self.moves,
                                           self.below, stay=0.0)
        return {name: basis for name, basis in out.items() if name in names}

    def auto(self, channels, location, gaps, seen):
        """Per gap, the candidate (:data:`AUTO_CANDIDATES` and ``stack``, ``learn`` on short
        gaps; :data:`AUTO_POSITIONS` where the knowledge base holds no bone rotations;
        :data:`TAKE_ALONE_CANDIDATES` without one) and the share of the way to it from the
        interpolation that refill copies of the gap best (:meth:`_judged`), or the interpolation;
        ``stack_long`` on long gaps none improves. A take without copies takes ``match`` on long
        gaps and ``mix`` on short ones (without a knowledge base ``hermite``, and part of the way
        to ``regress_kernel`` on long gaps), ``stack_long`` in equal parts where other bones'
        gaps overlap, and the interpolation where it and ``regress`` outvote ``match``. Then each
        gap's share is doubted and its kept part paired (:meth:`_made`), it goes on to the cubic,
        ``learn`` and the consensus of :data:`CONSENSUS_FILLS` (:meth:`_onward`), a gap at a clip
        end to the pair that agrees there (:meth:`_ends_agreed`), and a gap with two keys takes
        the fill the others bear out (:meth:`_assembled`)."""
        cfg = self.cfg
        alone = self.kb is None
        rotations = alone or self.kb.turns is not None
        if alone:
            self.report("no knowledge base: " + TAKE_ALONE.removeprefix("auto "))
        elif not rotations:
            self.report("the knowledge base holds no bone rotations (built from markers "
                        "or by an older version): filled from its joint positions; rebuild it "
                        "with 'kb build' from BVH or ASF/AMC takes for the rotation fill")
        names = (TAKE_ALONE_CANDIDATES if alone else AUTO_CANDIDATES if rotations
                 else AUTO_POSITIONS)
        copies = gap_copies(gaps, cfg.auto_copies, cfg.copy_margin)
        stack = rotations and bool(copies)  # the weights come from the copies
        runs = gap_runs(gaps)
        if alone:  # nothing to judge by: the cubic on short gaps, part of the way to the
            # take's own regression on long ones
            choice = [("hermite", 1.0) if (e - a + 1) < cfg.long_gap * self.fps
                      else ("regress_kernel", cfg.take_alone_unjudged) for _, a, e in runs]
        else:
            choice = [(names[0] if rotations and (e - a + 1) >= cfg.long_gap * self.fps
                       else names[1], 1.0) for _, a, e in runs]
        longest = [rotations and not self.short(a, e)
                   and (stack or np.count_nonzero(gaps[a:e + 1].any(axis=0)) > 1)
                   for _, a, e in runs]
        # in a take without copies, a long gap match fills unjudged goes on to the consensus
        unjudged = [rotations and not alone and not copies
                    and (e - a + 1) >= cfg.long_gap * self.fps for _, a, e in runs]
        # gaps a little too long for learn to be judged, with keys beyond their keys, go part
        # of the way on to it
        learnable = set(learnable_runs(gaps, cfg.learn_keys))
        mid = [rotations and bool(copies) and (b, a, e) in learnable
               and cfg.learn_seconds * self.fps <= e - a + 1 < cfg.mid_learn_seconds * self.fps
               for b, a, e in runs]
        # gaps at a clip end, where the consensus fills may agree on what the held key lacks
        ends = [rotations and not alone and cfg.ends_share > 0
                and stacking.keys_of(a, e, len(gaps)) != "both" for _, a, e in runs]
        fills = self.long_fills if any(longest) else self.stack_fills if stack else ()
        if any(unjudged):
            fills += tuple(f for f in self.consensus_fills if f not in fills)
        table = long_table = None  # the stacks' weights, from the copies
        if any(longest) and not copies:  # nothing to weigh the fills by: equal parts
            long_table = np.full((len(stacking.DISTANCES), len(stacking.LENGTHS), len(fills)),
                                 1 / len(fills))
            choice = [("stack_long", 1.0) if last else c for c, last in zip(choice, longest)]
        estimates, expected, pull, trusted, learns = self._unjudged(runs)
        if copies:
            (names, choice, estimates, expected, pull, learns, trusted, table,
             long_table) = self._judged(channels, location, gaps, seen, runs, copies, names,
                                        fills, stack, longest, learnable, choice)
        wanted, learn_mask, made, choice, corroborated = self._made(
            channels, location, gaps, seen, runs, choice, trusted, learns, mid, expected, fills,
            stack, longest, table, long_table, outvote=rotations and not alone and not copies)
        both = [rotations and not alone and bool(cfg.medoid_fills) and bool(copies)
                and not self.rig.roots[b] and stacking.keys_of(a, e, len(gaps)) == "both"
                for b, a, e in runs]
        paired_ends = self._alone(channels, location, gaps, seen, made, wanted, learn_mask,
                                  ((self.consensus_fills if any(ends) else ())
                                   + (cfg.medoid_fills if any(both) else ())))
        agreed = self._ends_agreed(paired_ends, runs, ends)
        wanted = learn_mask
        agree = cfg.consensus if wanted.any() and set(self.consensus_fills) <= set(made) else 0.0
        self._onward(runs, choice, estimates, corroborated, pull, trusted, longest, unjudged, mid,
                     agreed, agree)
        self._say(runs, choice, corroborated, pull, agreed)
        if not wanted.any() and not agreed.any() and not any(both):
            return seen
        return self._assembled(seen, runs, choice, corroborated, made, paired_ends, agreed,
                               both)

    def _unjudged(self, runs):
        """Per gap: no estimate of the error (as a share of the interpolation's, and the chosen
        fill's mean squared joint error), no pull to the cubic, no trust in ``learn``, ``learn``
        not judged: the start of every gap, and all there is in a take without copies."""
        nan = [float("nan")] * len(runs)
        return list(nan), list(nan), 0.0, [False] * len(runs), np.zeros(len(runs), bool)

    def _judged(self, channels, location, gaps, seen, runs, copies, names, fills, stack,
                longest, learnable, choice):
        """``auto``'s choice per gap from its copies: each candidate (and its blends with the
        interpolation at ``auto_shares``) refills the copies; per gap the mean log ratio of its
        error to the interpolation's over its own copies, shrunk towards the take's mean
        (``shrink``), picks the best under the bar (``promote``, ``promote_short``,
        ``promote_short_whole``). Returns ``(names, choice, estimates, expected, pull, learns,
        trusted, table, long_table)``: the candidates (``stack`` added where stacked), the
        choice, the estimated error as a share of the interpolation's and the expected mean
        squared joint error, how far the kept interpolation goes to the cubic, where ``learn``
        is judged and trusted, and the stacks' weights."""
        cfg = self.cfg
        estimates, expected, pull, trusted, learns = self._unjudged(runs)
        table = long_table = None
        probe = np.zeros_like(gaps)
        for _, b, start, length in copies:
            probe[start:start + length, b] = True
        hidden = interpolate_channels(channels, probe)
        hidden_loc = np.where((probe & self.moves)[..., None],
                              interpolate_channels(location, probe), location)
        # learn only where it is judged: short gaps with keys beyond their keys, and copies
        learns = np.array([e - a + 1 < cfg.learn_seconds * self.fps and (b, a, e) in learnable
                           for b, a, e in runs])
        if cfg.learn_pull and learns.any():  # how often learn loses the bone's windows
            losses = learn_losses(seen[..., :3, :3], channels, self.rig.modes, gaps,
                                  self.rig.levers(), cfg.learn_keys, cfg.learn_ridge,
                                  plus=0.002 / self.metre_scale())
            trusted = [learns[i] and losses.get(run, 1.0) <= cfg.learn_trust
                       for i, run in enumerate(runs)]
        judged = np.zeros_like(gaps)
        for i, b, start, length in copies:
            judged[start:start + length, b] = learns[i]
        tried = self.candidates(hidden, hidden_loc, gaps | probe, ("interp",) + names + fills,
                                seen, learn_on=(gaps | probe, judged))
        truth = self.world(seen)
        if stack:  # each copy stacked with weights its own gap's copies had no part in
            table, by_gap, long_table = self._stack_tables(tried, truth, copies, fills)
            of_copy = {(b, start): by_gap[i] for i, b, start, _ in copies}
            tried["stack"] = self._stacked(tried, gaps | probe, self.stack_fills,
                                           lambda b, a: of_copy.get((b, a), table))
            names = names + ("stack",)
        base = self._errors(tried["interp"], truth, copies)
        samples = np.array([c[3] * np.count_nonzero(self.moved_by(c[1])) for c in copies])
        # log error ratio to interpolation per copy (1 mm^2 per joint and frame keeps still
        # bones at 0); per gap the mean over its copies, shrunk towards the take's mean
        floor = np.array([1e-6 * c[3] * (self.below[c[1]].sum() + 1) for c in copies])
        if stack:  # how far all the copies together favour the cubic
            favour = -np.mean(np.log((self._errors(tried["hermite"], truth, copies) + floor)
                                     / (base + floor)))
            pull = min(cfg.cubic_pull, max(0.0, favour - cfg.cubic_trust))
        owner = np.array([c[0] for c in copies])
        everywhere, learnt = np.ones(len(copies), bool), learns[owner]
        ratio = {}
        for name in names:
            for share in cfg.auto_shares:
                blend = halfway(tried["interp"], tried[name], gaps | probe, share)
                ratio[name, share] = np.log((self._errors(blend, truth, copies) + floor)
                                            / (base + floor))
        for i, (b, a, e) in enumerate(runs):
            long = (e - a + 1) >= cfg.long_gap * self.fps
            own = owner == i
            score = {key: (r[own].sum() + cfg.shrink * r[among].mean())
                     / (own.sum() + cfg.shrink)
                     for key, r in ratio.items()  # learn: among the copies it fills
                     for among in [learnt if key[0] == "learn" else everywhere]
                     if among.any() and (key[0] != "learn" or learns[i])}
            passed = {key: value for key, value in score.items() if value < np.log(
                cfg.promote if long else cfg.promote_short_whole if key[1] == 1
                else cfg.promote_short)}
            choice[i] = (min(passed, key=passed.get) if passed else
                         ("stack_long", 1.0) if longest[i] else ("interp", 0.0))
            if (longest[i] and own.sum() < cfg.auto_copies
                    and e - a + 1 >= cfg.few_copies * self.fps):
                choice[i] = ("stack_long", 1.0)  # too few copies of its own to judge by
            if choice[i] in score:  # as a ratio of RMS errors, not of squared ones
                estimates[i] = float(np.exp(score[choice[i]] / 2))
                if own.any():  # that ratio of the interpolation's RMS error on them
                    expected[i] = (estimates[i]
                                   * np.mean(np.sqrt(base[own] / samples[own]))) ** 2
        return names, choice, estimates, expected, pull, learns, trusted, table, long_table

    def _made(self, channels, location, gaps, seen, runs, choice, trusted, learns, mid, expected,
              fills, stack, longest, table, long_table, outvote):
        """The fills the chosen ones need, made for the gaps that take one (``wanted``; with
        ``learn`` also where it is trusted or goes part of the way, ``learn_mask``); the stacks
        from their weights; each choice doubted where the fills disagree and paired where two
        agree (:meth:`_doubted`, :meth:`_corroborated`), and in a take without copies
        ``outvote``d (:meth:`_outvoted`). Returns ``(wanted, learn_mask, made, choice,
        corroborated)``."""
        cfg = self.cfg
        wanted = np.zeros_like(gaps)
        for (b, a, e), (name, _), trust in zip(runs, choice, trusted):  # a short gap may take a
            # pair's mean and learn
            wanted[a:e + 1, b] = name != "interp" or (stack and self.short(a, e)) or trust
        corroborated, made = [None] * len(runs), {}
        learn_mask = wanted.copy()  # learn fills these too; match's context is the gaps it fills
        for (b, a, e), middle in zip(runs, mid):
            learn_mask[a:e + 1, b] |= middle
        paired = stack and cfg.corroborate_learn > 0 and learns.any()
        with_learn = {"learn"} if any(trusted) or any(mid) or paired else set()
        if wanted.any():
            made = self.candidates(channels, location, wanted,
                                   {name for name, _ in choice} | set(fills) | with_learn, seen,
                                   learn_on=(gaps, learn_mask))
            if stack:
                made["stack"] = self._stacked(made, wanted, self.stack_fills,
                                              lambda b, a: table)
                choice = self._doubted(made, runs, choice, expected)
                corroborated = self._corroborated(made, runs, choice,
                                                  learns if paired else None)
            if any(longest):
                made["stack_long"] = self._stacked(made, wanted, self.long_fills,
                                                   lambda b, a: long_table)
            if outvote:
                choice = self._outvoted(channels, location, wanted, seen, made, runs, choice)
        elif any(mid):
            made = self.candidates(channels, location, learn_mask, with_learn, seen,
                                   learn_on=(gaps, learn_mask))
        return wanted, learn_mask, made, choice, corroborated

    def _alone(self, channels, location, gaps, seen, made, wanted, learn_mask, names):
        """The ``names`` fills (and ``interp``) as each fills the take's gaps alone: the pair at
        clip ends (neither is judged there) and the medoid's voters on the gaps with two keys;
        those ``made`` for every gap already are the same ({} where no names)."""
        if not names:
            return {}
        whole = np.array_equal(wanted, gaps)
        same = {name: made[name] for name in names if whole and name in made
                and (name != "learn" or np.array_equal(learn_mask, gaps))}
        return {**self.candidates(channels, location, gaps, ("interp", *(
            name for name in names if name not in same)), seen), **same}

    def _onward(self, runs, choice, estimates, corroborated, pull, trusted, longest, unjudged,
                mid, agreed, agree):
        """What each gap's fill goes on to (the cubic, ``learn``, the consensus at ``agree`` of the
        way, the pair at a clip end), kept on the job for :func:`fill_bones`' choices."""
        cfg = self.cfg
        towards = self.consensus_fills
        self.choices, self.estimates, self.corroborated = choice, estimates, corroborated
        self.cubic = [pull * (1 - share) if share < 1 and self.short(a, e) else 0.0
                      for (_, a, e), (_, share) in zip(runs, choice)]
        self.learnt = [cfg.learn_pull * (1 - share) if trust else 0.0
                       for trust, (_, share) in zip(trusted, choice)]
        onward = [agree if last else cfg.unjudged_consensus * bool(agree) if unjudged_gap else 0.0
                  for last, unjudged_gap in zip(longest, unjudged)]
        self.consensus = [cfg.mid_learn if middle else on if name != "interp"
                          and (share < 1 or set(towards) != {name}) else 0.0  # there already
                          for (name, share), on, middle in zip(choice, onward, mid)]
        self.towards = [("learn",) if middle else towards if on else ()
                        for on, middle in zip(self.consensus, mid)]
        for i in np.flatnonzero(agreed):  # on from the fill and its consensus, if any
            self.consensus[i] = 1 - (1 - self.consensus[i]) * (1 - cfg.ends_share)
            self.towards[i] = self.consensus_fills

    def _say(self, runs, choice, corroborated, pull, agreed):
        """What ``auto`` did to the gaps, in one line for ``trace`` (``--verbose``)."""
        cfg = self.cfg
        counts, partly = {}, {}
        for name, share in choice:
            name = name if share else "interp"  # doubted all the way back
            counts[name] = counts.get(name, 0) + 1
            partly[name] = partly.get(name, 0) + (0 < share < 1)
        onwards = "; ".join(
            f"{n} {'long' if onto == self.consensus_fills else 'mid-length'} gaps "
            f"{'to the mean of' if on == 1 else f'{on:.0%} of the way on to'} {' + '.join(onto)}"
            for (on, onto), n in Counter((on, onto) for on, onto in zip(self.consensus,
                                                                        self.towards) if on
                                         ).items())
        pairs = sum(pair is not None for pair in corroborated)
        with_pairs_of_learn = any(pair and "learn" in pair for pair in corroborated)
        self.trace("auto: " + ", ".join(
            f"{name} on {n} of {len(runs)} gaps"
            + (f" ({partly[name]} part of the way from the interpolation)" if partly[name] else "")
            for name, n in counts.items())
            + (f"; then {onwards}" if onwards else "")
            + (f"; the interpolated part of {pairs} short gaps {cfg.corroborate:.0%} of the way "
               "on to two fills that agree there"
               + (f" ({cfg.corroborate_learn:.0%} where one is learn)"
                  if with_pairs_of_learn else "") if pairs else "")
            + (f"; the interpolated part of the short gaps {pull:.0%} of the way on to the cubic, "
               "which the take's copies favour" if any(self.cubic) else "")
            + (f"; the interpolated part of {sum(map(bool, self.learnt))} short gaps "
               f"{cfg.learn_pull:.0%} of the way on to learn, which the bone's own windows trust"
               if any(self.learnt) else "")
            + (f"; {sum(agreed)} gaps at a clip end {cfg.ends_share:.0%} of the way on to "
               f"{' + '.join(self.consensus_fills)}, which agree there" if any(agreed) else ""))

    def _assembled(self, seen, runs, choice, corroborated, made, paired_ends, agreed, both):
        """The take with each gap filled as chosen: from the interpolation ``seen`` its share
        of the way to its fill (about the interpolation, with the pair's mean, the cubic and
        ``learn`` where it goes on to them), then on to its consensus; last the fill the others
        bear out in the place of a gap with two keys (:meth:`_medoid`)."""
        cfg = self.cfg
        out = seen.copy()
        for (b, a, e), (name, share), further, onto, pair, cubic, to_learn, end in zip(
                runs, choice, self.consensus, self.towards, corroborated, self.cubic,
                self.learnt, agreed):
            rows, span = slice(a, e + 1), np.ones((e - a + 1, 1), bool)
            if pair or cubic or to_learn:  # about the interpolation: the fill's share, on the
                # rest the pair's mean, the cubic and learn
                fill = _about(seen[rows, b], [(made[name][rows, b], share)] + [
                    (made[key][rows, b], (cfg.corroborate_learn if "learn" in pair
                                          else cfg.corroborate) * (1 - share) / 2)
                    for key in pair or ()]
                    + [(made[key][rows, b], weight) for key, weight
                       in (("hermite", cubic), ("learn", to_learn)) if weight])[:, None]
            elif name != "interp" and share:
                fill = halfway(seen[rows, b:b + 1], made[name][rows, b:b + 1], span, share)
            else:
                fill = seen[rows, b:b + 1]
            if further:  # the mean of the fills, each of k taking 1/k of the way
                source = paired_ends if end else made
                target = source[onto[0]][rows, b:b + 1]
                for k, key in enumerate(onto[1:], 2):
                    target = halfway(target, source[key][rows, b:b + 1], span, 1 / k)
                fill = halfway(fill, target, span, further)
            out[rows, b] = fill[:, 0]
        self.medoids = self._medoid(out, paired_ends, runs, both)
        for (b, a, e), name in zip(runs, self.medoids):
            if name:
                out[a:e + 1, b] = paired_ends[name][a:e + 1, b]
        if any(self.medoids):
            self.trace(f"auto: {sum(map(bool, self.medoids))} of {sum(both)} gaps with two keys "
                        f"take the one of {' / '.join(cfg.medoid_fills)} that lies nearer the "
                        "other fills than their own")
        return out

    def _medoid(self, filled, alone, runs, both):
        """Per gap, the fill of ``medoid_fills`` (in ``alone``) to take instead of
        ``filled``'s, where it has the least summed RMS distance to the others of the fills and
        ``filled`` ("": ``filled`` has). Gaps of bones one above the other that overlap in time
        are decided together (:meth:`_chains`), over the joints they move and the frames they
        span: a chain's rotations from different fills do not fit together. Only groups of
        gaps that are all ``both``."""
        out = [""] * len(runs)
        groups = [(group, moved) for group in self._chains(runs) if all(both[i] for i in group)
                  for moved in [np.logical_or.reduce([self.moved_by(runs[i][0]) for i in group])]
                  if moved.any()]
        if not groups:
            return out
        spans = []
        for group, _ in groups:
            first, last = min(runs[i][1] for i in group), max(runs[i][2] for i in group)
            spans.append((None, None, first, last - first + 1))
        keys = ("",) + self.cfg.medoid_fills
        worlds = {key: self._spans(alone[key] if key else filled, spans) for key in keys}
        for k, (group, moved) in enumerate(groups):
            at = {key: world[k][:, moved] for key, world in worlds.items()}
            nearest = min(keys, key=lambda x: sum(_rms_apart(at, x, y) for y in keys))
            for i in group:
                out[i] = nearest
        return out

    def _chains(self, runs):
        """The gaps (``runs``' indices) in groups: two gaps whose frames overlap, of bones one
        above the other (:meth:`~.rig.Rig.placed_by`), are in one group."""
        group = list(range(len(runs)))

        def top(i):
            while group[i] != i:
                i = group[i]
            return i

        for i, (b, a, e) in enumerate(runs):
            for j, (c, a2, e2) in enumerate(runs[:i]):
                if a <= e2 and a2 <= e and (self.below[c, b] or self.below[b, c]):
                    group[top(i)] = top(j)
        out = {}
        for i in range(len(runs)):
            out.setdefault(top(i), []).append(i)
        return list(out.values())

    def _outvoted(self, channels, location, wanted, seen, made, runs, choice):
        """``choice`` in a take without copies, where ``match`` fills every gap of
        ``long_gap`` seconds or more unjudged: such a gap keeps the interpolation where it
        and ``regress`` (the take's own regression, no knowledge base) lie within
        ``outvoted`` of ``match``'s distance from the nearer of them, over the joints the
        gap's bone moves. Two estimates that owe each other nothing outvote the knowledge
        base's."""
        judged = [i for i, ((_, a, e), (name, _)) in enumerate(zip(runs, choice))
                  if name == "match" and e - a + 1 >= self.cfg.long_gap * self.fps]
        if not judged:
            return choice
        fills = {**made, **self.candidates(channels, location, wanted,
                                           {"interp", "regress"} - set(made), seen)}
        world = {name: self.world(fills[name]) for name in ("interp", "regress", "match")}
        out = list(choice)
        for i in judged:
            b, a, e = runs[i]
            joints = self.moved_by(b)

            def apart(x, y):
                return np.sqrt(np.mean((world[x][a:e + 1, joints]
                                        - world[y][a:e + 1, joints]) ** 2))

            if apart("regress", "interp") < self.cfg.outvoted * min(apart("match", "interp"),
                                                           apart("match", "regress")):
                out[i] = ("interp", 0.0)
        return out

    def _doubted(self, made, runs, choice, expected):
        """``choice`` with the share of each gap shorter than ``long_stack`` cut to ``A / (A
        + auto_doubt * D)`` of itself: ``A`` the squared joint departure of the share's blend
        from ``interp`` on the gap, ``D`` the mean squared spread of the stacked fills (those of
        :data:`STACK_FILLS` but ``interp``) about their stack there: the fills that agree on the
        gap are believed, the others hardly. Then, where the gap's copies ``expected`` the fill
        an error (mean squared, per joint and frame; NaN: unknown), by ``max(0, 1 - auto_wary *
        expected / a)``, ``a`` the mean squared departure so cut: a gap calmer than its copies
        departs little beyond the fill's own error, and keeps about the interpolation (the
        gaps the fill lost, docs/DESIGN.md and 50). Longer gaps keep their
        fill."""
        spans = [(i, b, a, e - a + 1) for i, ((b, a, e), (name, _)) in enumerate(zip(runs, choice))
                 if name != "interp" and self.short(a, e)]
        if not spans:
            return choice
        worlds = {key: self._spans(made[key], spans)
                  for key in {"stack", *self.stack_fills} | {choice[i][0] for i, *_ in spans}}
        choice = list(choice)
        for k, (i, b, _, _) in enumerate(spans):
            name, share = choice[i]
            joints = self.moved_by(b)
            at = {key: worlds[key][k][:, joints] for key in {name, "stack", *self.stack_fills}}
            away = share ** 2 * np.sum((at[name] - at["interp"]) ** 2)
            doubt = np.mean([np.sum((at[fill] - at["stack"]) ** 2)
                             for fill in self.stack_fills[1:]])
            cut = float(away / (away + self.cfg.auto_doubt * doubt + 1e-12))
            if np.isfinite(expected[i]):  # the departure so cut, per joint and frame
                departure = cut ** 2 * away / (at[name].shape[0] * at[name].shape[1])
                cut *= max(0.0, 1 - self.cfg.auto_wary * expected[i] / max(departure, 1e-18))
            choice[i] = (name, share * cut)
        return choice

    def _ends_agreed(self, made, runs, ends):
        """Per gap, whether it lies at a clip end (``ends``) where the fills of
        :data:`CONSENSUS_FILLS` in ``made`` lie apart by less than ``corroborated`` times
        their mean departure from the held key (RMS over the joints the gap's bone moves)."""
        spans = [(i, b, a, e - a + 1) for i, ((b, a, e), end) in enumerate(zip(runs, ends))
                 if end and self.moved_by(b).any()]
        out = np.zeros(len(runs), bool)
        if not spans:
            return out
        x, y = self.consensus_fills
        worlds = {key: self._spans(made[key], spans) for key in ("interp", x, y)}
        for k, (i, b, _, _) in enumerate(spans):
            apart, away = _apart({key: world[k][:, self.moved_by(b)]
                                  for key, world in worlds.items()}, x, y)
            out[i] = away > 0 and apart < self.cfg.corroborated * away
        return out

    def _corroborated(self, made, runs, choice, learns=None):
        """Per gap shorter than ``long_stack`` that keeps part of the interpolation (share
        below 1), the two stacked fills (of :data:`STACK_FILLS` but ``interp``) that lie closest
        together as a share of their mean departure from ``interp`` (RMS over the joints the
        gap's bone moves), where that share is below ``corroborated``: the cubic from the
        keys, the take's own regression and the knowledge base's motion owe each other nothing,
        so where two of them agree on a motion the interpolation lacks, it is there (on the
        non-test takes, docs/DESIGN.md). ``learns`` (per gap, or None): where
        ``learn`` may be one of the two (``corroborate_learn``). None
        elsewhere."""
        fills = [f for f in self.stack_fills if f != "interp"]
        spans = [(i, b, a, e - a + 1) for i, ((b, a, e), (_, share)) in enumerate(zip(runs, choice))
                 if share < 1 and self.short(a, e) and self.moved_by(b).any()]
        out = [None] * len(runs)
        if not spans or len(fills) < 2:
            return out
        more = [] if learns is None else ["learn"]
        worlds = {key: self._spans(made[key], spans) for key in ("interp", *fills, *more)}
        for k, (i, b, _, _) in enumerate(spans):
            joints = self.moved_by(b)
            at = {key: world[k][:, joints] for key, world in worlds.items()}
            some = fills + more if more and learns[i] else fills
            ratios = {(x, y): apart / max(away, 1e-12)
                      for m, x in enumerate(some) for y in some[m + 1:]
                      for apart, away in [_apart(at, x, y)]}
            pair = min(ratios, key=ratios.get)
            if ratios[pair] < self.cfg.corroborated:
                out[i] = pair
        return out

    def _stack_tables(self, made, truth, copies, fills):
        """The ``stack`` weights (:func:`~.stacking.weights`) the copies' errors give for the
        fills of :data:`STACK_FILLS`: over every copy, and per gap (index) over the copies of
        the other gaps; and ``stack_long``'s over every copy where ``fills`` is
        :data:`LONG_STACK_FILLS` (else None). The errors' moments are taken once, for
        ``fills``: those of :data:`STACK_FILLS` are their leading block."""
        cfg = self.cfg
        worlds = [self._spans(made[name], copies) for name in fills]
        per_gap, total = {}, (0.0, 0.0)
        for k, (i, b, start, length) in enumerate(copies):
            joints, span = self.moved_by(b), slice(start, start + length)
            moments = stacking.moments(
                [world[k][:, joints] - truth[span, joints] for world in worlds], self.fps)
            per_gap[i] = tuple(a + m for a, m in zip(per_gap.get(i, (0.0, 0.0)), moments))
            total = tuple(a + m for a, m in zip(total, moments))
        n = len(self.stack_fills)
        table = stacking.weights(total[0][..., :n, :n], total[1], cfg.stack_ridge)
        alone = {i: stacking.weights((total[0] - sums)[..., :n, :n], total[1] - counts,
                                     cfg.stack_ridge) for i, (sums, counts) in per_gap.items()}
        return table, alone, (stacking.weights(*total, cfg.stack_ridge) if len(fills) > n else None)

    def _stacked(self, made, mask, fills, table_of):
        """``stack``: on each run of ``mask`` the ``fills`` weighed together frame by frame
        (rotations about ``interp``'s, locations on the line), the weights from
        ``table_of(bone, first frame of the run)``, each frame's by its distance from the run's
        keys: at a clip end from its one key."""
        out = made["interp"].copy()
        for b, a, e in gap_runs(mask):
            w = stacking.frame_weights(table_of(b, a), e - a + 1, self.fps,
                                       stacking.keys_of(a, e, len(mask)))
            out[a:e + 1, b] = _about(out[a:e + 1, b], [(made[name][a:e + 1, b], w[:, k:k + 1])
                                                       for k, name in enumerate(fills)])
        return out

    def _errors(self, basis, truth, copies):
        """Squared joint error (metres^2, summed) of each copy: the joints its bone moves."""
        out = np.empty(len(copies))
        for i, (world, (_, b, start, length)) in enumerate(zip(self._spans(basis, copies),
                                                               copies)):
            joints = self.moved_by(b)
            out[i] = np.nansum((world[:, joints] - truth[start:start + length, joints]) ** 2)
        return out

    def _spans(self, basis, copies):
        """The world joints of ``basis`` on each copy's frames (posed on those frames only)."""
        rows = np.unique(np.concatenate([np.arange(c[2], c[2] + c[3]) for c in copies]
                                        or [np.zeros(0, int)]))
        world = self.world(basis[rows])
        first = np.searchsorted(rows, [c[2] for c in copies])
        return [world[f:f + c[3]] for f, c in zip(first, copies)]


def carry_subtrees(rig, basis, gaps, targets, moves, below=None, stay=BoneConfig.stay):
    """Basis matrices where each gapped bone (top-down) takes the location that puts its head
    on its target (moving bones) and the rotation that best carries the joints it moves, posed
    by their own channels, onto their targets (Kabsch about its head; the smallest turn from
    the current rotation where those joints are collinear, which keeps the current twist).
    ``stay`` weighs the current rotation in the fit (0: the targets alone)."""
    basis = np.array(basis, dtype=float)
    below = rig.placed_by() if below is None else below
    parents = rig.parents
    local = np.linalg.inv(rig.rest)
    for b in order_bones(parents):
        frames = np.flatnonzero(gaps[:, b])
        if not len(frames):
            continue
        pose = forward(rig.rest, parents, basis[frames])
        p = parents[b]
        above = rig.rest[b] if p < 0 else pose[:, p] @ local[p] @ rig.rest[b]
        above = np.broadcast_to(above, (len(frames), 4, 4))
        if moves[b] and (rig.lengths is None or p < 0):
            aim = targets[frames, b]
            ok = np.isfinite(aim[:, 0])
            basis[frames[ok], b, :3, 3] = np.einsum("fji,fj->fi", above[ok, :3, :3],
                                                    aim[ok] - above[ok, :3, 3])
        joints = np.flatnonzero(below[b])
        if not len(joints):
            continue
        # joints that another gapped bone below this one moves have no known shape here
        others = gaps[frames] & below[b]
        others[:, b] = False
        use = ~((others.astype(np.int64) @ below.astype(np.int64)) > 0)[:, joints]
        aim = targets[frames][:, joints]
        use &= np.isfinite(aim[..., 0])
        ok = use.any(axis=1)
        if not ok.any():
            continue
        frames, above, aim, use = frames[ok], above[ok], np.nan_to_num(aim[ok]), use[ok]
        frame_of_bone = above @ basis[frames, b]  # with the current rotation
        now = rig.joints(basis[frames])[:, joints]
        inv = np.linalg.inv(frame_of_bone)
        y = (np.einsum("fij,fkj->fki", inv[:, :3, :3], now) + inv[:, None, :3, 3]) * use[..., None]
        inv_above = np.linalg.inv(above)
        w = (np.einsum("fij,fkj->fki", inv_above[:, :3, :3], aim) + inv_above[:, None, :3, 3]
             - basis[frames, b, None, :3, 3]) * use[..., None]
        current = basis[frames, b, :3, :3]
        # pseudo-points that pull towards the current rotation: joints near the bone's axis
        # (fingers about a forearm) would otherwise turn it on the targets' noise
        pull = np.sqrt(stay * (y ** 2).sum(axis=(1, 2)))[:, None, None] * np.eye(3)
        turn, determined = best_rotation(np.concatenate([y, pull], axis=1),
                                          np.concatenate([w, pull @ np.swapaxes(current, 1, 2)],
                                                         axis=1))
        # collinear joints leave the twist free: keep the current one
        mean_y = np.einsum("fij,fj->fi", current, y.sum(axis=1))
        smallest = rotation_between(mean_y, w.sum(axis=1)) @ current
        basis[frames, b, :3, :3] = np.where(determined[:, None, None], turn, smallest)
    return basis


def _damped(shape, pred, seen, known, a, e):
    """The windows' rotations over a gap (frames a..e of the stretch), their turn away from the
    slerp between their ends scaled by how fast the take's bone turns beside the gap against
    how fast the windows' does there (at most 1): a bone the take holds still stays still."""
    pairs = [t for t in range(len(pred) - 1)
             if known[t] and known[t + 1] and not a - 1 <= t <= e]
    if not pairs:
        return shape

    def speed(r):
        rel = np.einsum("tji,tjk->tik", r[pairs], r[[t + 1 for t in pairs]])
        return np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)).sum()

    share = min(1.0, speed(seen) / max(speed(pred), 1e-9))
    if share >= 1.0:
        return shape
    span = np.arange(a, e + 1)
    line = Slerp([a - 1, e + 1], Rotation.from_matrix(pred[[a - 1, e + 1]]))(span).as_matrix()
    turn = Rotation.from_matrix(shape @ np.swapaxes(line, 1, 2)).as_rotvec() * share
    return Rotation.from_rotvec(turn).as_matrix() @ line


def _orthonormal(six):
    """Rotation matrices (..., 3, 3) nearest in Gram-Schmidt's sense to the first two columns
    given as (..., 6) (row-major of a (3, 2) block)."""
    cols = six.reshape(six.shape[:-1] + (3, 2))
    return gram_schmidt(cols[..., 0], cols[..., 1])


def halfway(start, end, gaps, share=0.5):
    """Basis matrices ``share`` of the way from ``start`` to ``end`` on the gap frames (rotations
    along the shortest turn, locations on the straight line)."""
    out = start.copy()
    a, b = Rotation.from_matrix(start[gaps][:, :3, :3]), Rotation.from_matrix(end[gaps][:, :3, :3])
    part = out[gaps]
    part[:, :3, :3] = (Rotation.from_rotvec((b * a.inv()).as_rotvec() * share) * a).as_matrix()
    part[:, :3, 3] = start[gaps][:, :3, 3] * (1 - share) + end[gaps][:, :3, 3] * share
    out[gaps] = part
    return out


def _rms_apart(at, x, y):
    """How far fills ``x`` and ``y`` lie apart: the RMS of their joint distances (``at``: each
    fill's joints, (frames, joints, 3), by name)."""
    return np.sqrt(np.mean(np.sum((at[x] - at[y]) ** 2, axis=-1)))


def _apart(at, x, y):
    """How far fills ``x`` and ``y`` lie apart and their mean departure from ``interp``
    (:func:`_rms_apart`)."""
    return _rms_apart(at, x, y), 0.5 * (_rms_apart(at, x, "interp") + _rms_apart(at, y, "interp"))


def _about(base, parts):
    """Basis matrices (frames, 4, 4): ``base`` turned by the weighted sum of the turns from it
    to each of ``parts`` ((matrices, weight) pairs, a weight a number or one per frame, (frames,
    1); rotation vectors summed), located at the weighted sum of the moves from it: ``stack``'s
    fills weighed frame by frame, a short gap's share of its fill and of an agreeing pair."""
    origin = Rotation.from_matrix(base[:, :3, :3])
    turn = sum(weight * (Rotation.from_matrix(other[:, :3, :3]) * origin.inv()).as_rotvec()
               for other, weight in parts)
    out = base.copy()
    out[:, :3, :3] = (Rotation.from_rotvec(turn) * origin).as_matrix()
    out[:, :3, 3] = base[:, :3, 3] + sum(weight * (other[:, :3, 3] - base[:, :3, 3])
                                         for other, weight in parts)
    return out


def _slerp(basis, gaps, moves):
    out = basis.copy()
    frames = len(basis)
    for b, a, e in gap_runs(gaps):
        ends = [t for t in (a - 1, e + 1) if 0 <= t < frames]
        if len(ends) < 2:
            continue  # at a clip end the held key is all there is
        rot = Rotation.from_matrix(basis[ends, b, :3, :3])
        out[a:e + 1, b, :3, :3] = Slerp(ends, rot)(np.arange(a, e + 1)).as_matrix()
        if moves[b]:
            w = ((np.arange(a, e + 1) - ends[0]) / (ends[1] - ends[0]))[:, None]
            out[a:e + 1, b, :3, 3] = basis[ends[0], b, :3, 3] * (1 - w) + basis[ends[1], b, :3, 3] * w
    return out


def gap_copies(gaps, per_gap=3, margin=10):
    """Copies of each gap where its bone is keyed: ``(gap index, bone, start, length)``, the
    gap index into :func:`~.motion.gap_runs` order; up to ``per_gap`` per gap, at the nearest
    shifts (by at least the gap's length plus ``margin``) that keep ``margin`` keyed frames
    to every gap and copy of that bone, with a key on each side."""
    frames = len(gaps)
    taken = gaps.copy()
    out = []
    for i, (b, a, e) in enumerate(gap_runs(gaps)):
        length = e - a + 1
        step = length + margin
        found = 0
        for k in range(1, frames // max(step, 1) + 2):
            for start in (a - k * step, a + k * step):
                lo, hi = start - margin, start + length + margin
                if start < 1 or start + length > frames - 1:
                    continue
                if taken[max(lo, 0):min(hi, frames), b].any():
                    continue
                taken[start:start + length, b] = True
                out.append((i, b, start, length))
                found += 1
                if found == per_gap:
                    break
            if found == per_gap:
                break
    return out
