"""One entry point for every gap-filling method: :func:`fill`."""

import warnings
from dataclasses import dataclass, replace

import numpy as np

from . import baselines
from .errors import GapFillError
from .kb import match_names, starter_kb
from .motion import gap_runs
from .performers import bare, names_for_kb, performers
from .matching import MatchSettings
from .regression import RegressionSettings

METHODS = ("knn", "auto", "linear", "spline", "local-spline", "rigid", "pattern", "svt", "pca",
           "intercorrelation")
#: what ``fill`` (the command, the add-on) uses unless told otherwise
DEFAULT_METHOD = "auto"
#: the methods that are not the project's own (what users already have, and the literature's)
BASELINES = tuple(m for m in METHODS if m not in ("knn", "auto"))
#: the methods that use a knowledge base when there is one (the command and the add-on then take
#: the starter one that fits), and those that cannot fill without one (``auto`` fills from the
#: take alone: rigid partners, a spline, a partner's pattern)
USES_KB = ("knn", "auto", "pca")
NEEDS_KB = ("knn", "pca")
#: what ``auto`` does where no knowledge base fits, in words
TAKE_ALONE = "auto fills from the take alone (rigid partners, a spline, a partner's pattern)"
@dataclass(frozen=True)
class AutoConfig:
    """What ``auto`` on markers and skeleton joints goes by; ``fill(..., config=AutoConfig(...))``.
    The defaults were chosen on takes that are not test takes."""

    #: validation gaps (copies of its gaps) per point for ``auto``, and for skeleton joints more
    #: where those hold fewer frames than ``probe_frames`` (five copies of 3-frame dropouts weigh
    #: the methods on 15 samples; on marker sets rigid partners carry nearly every marker with short
    #: gaps alone either way, and the extra copies only cost time: docs/DESIGN.md); a point whose
    #: copies hold fewer frames, markers too, has its gaps copied again, further off (one copy alone
    #: misjudged a marker's one gap, the last 15 frames of a take: 24 mm where its rigid partners
    #: alone made 4.5; docs/DESIGN.md)
    probes: int = 5
    probe_frames: int = 30
    #: metres: on a marker set, pairs whose distance strays by at most this much (SD) are kept last,
    #: each as far as its spread lets it (docs/DESIGN.md); a skeleton keeps its exact ones
    #: (baselines.RIGID_TIE) exactly
    kept_spread: float = 0.005
    #: on a marker set each such pair aims this share of the way from the take's mean distance to
    #: its own distance about the gap (interpolated from where both ends are seen): the distance
    #: drifts as the body turns its joints (docs/DESIGN.md)
    kept_local: float = 0.5
    #: ... and, at a frame where one of its ends is seen, counts as this many times its variance: a
    #: marker alone in a gap is placed among its seen partners already, and the error its gap
    #: expects (from copies) is right on the mean, not per gap (docs/DESIGN.md)
    kept_seen: float = 2.0
    #: donors of ``auto``'s rigid-body estimate
    donors: int = 3
    #: ``auto`` lets rigid partners alone carry a point whose copies they refill better than the
    #: knowledge base and within this RMS error (metres); the knowledge base then sees it as
    #: observed. Skeleton joints ride on exactly rigid bones; skin markers shift against each other
    #: by millimetres, so a marker set allows more
    rigid_first: float = 0.005
    rigid_first_markers: float = 0.02
    #: for markers (not skeleton joints), ``auto``'s rigid-body estimate also carries a point from
    #: the nearest frames (within this many gap lengths) where its steadiest donors are seen,
    #: weighed with the estimate from the gap's ends. A skeleton's steadiest partners are often its
    #: neighbours along a bone chain (a bone's length is constant, the chain still bends), which
    #: frames further away carry wrong
    reach: int = 3
    #: copies shorter than the gaps (a take with no room for full-length ones, e.g. a limb gone for
    #: half of it) flatter the rigid estimate, whose error grows with the distance from the gap's
    #: ends: its error on them is raised to at least this many times its donors' mean squared spread
    #: over the gaps, times (gap length / copy length - 1), at most 1
    spread_cap: float = 2.0
    #: skeleton joints whose gaps last this many seconds on the mean also get the knowledge base's
    #: windows of motion (:func:`~.matching.fill_match`) beside its per-frame models, the two
    #: weighted by their errors on the point's copies: a limb gone for seconds takes real motion of
    #: a body that moved like this one (on shorter gaps the windows' mean misses the pose the models
    #: fit; on marker sets the windows never refilled the copies better, and cost time); and the
    #: take's own regression of the point on the points seen through the gap
    #: (:func:`~.regression.regress_points`), weighted by its errors on the copies (on shorter gaps
    #: and on marker sets it misled the copies: docs/DESIGN.md); without a knowledge base the
    #: regression (and the pattern below) alone stand in for it, from ``alone_seconds``
    match_seconds: float = 1.0
    #: without a knowledge base the take's own regression and a partner's pattern join a skeleton
    #: joint whose gaps last this many seconds on the mean (with one they would mislead the models
    #: on shorter gaps; without one they are weighed against the rigid partners alone:
    #: docs/DESIGN.md)
    alone_seconds: float = 0.5
    #: on those points a partner's pattern (:func:`~.baselines.fill_pattern`) joins the knowledge
    #: base's estimate too where it refills the copies better still, its error on them raised to at
    #: least this many times the variance of its offset to its steadiest partner seen through the
    #: gaps: short copies of a limb gone for seconds flatter a partner whose offset wanders (a leg
    #: follows the other through jumps and squats, not through a walk; docs/DESIGN.md)
    pattern_floor: float = 0.5
    #: the windows and the partner's pattern join only where they refilled the copies better than
    #: the rest of the knowledge base's estimate, their share opening gradually: 0 at equal errors,
    #: the full inverse-error share where that share is this far above one half (a step there let
    #: rounding at the thousandth of a mm flip a point's fill: docs/DESIGN.md)
    join_ramp: float = 0.1
    #: gaps of at most this many seconds are also blended with a spline through the take
    #: (:func:`_with_spline`), by its error on up to ``spline_copies`` copies of each gap, kept
    #: ``spline_margin`` frames from any gap and within ``spline_reach`` gap lengths of theirs
    #: (tuned, docs/DESIGN.md: over longer gaps a spline's error has a tail that its copies do not
    #: foresee)
    spline_seconds: float = 0.2
    #: longer gaps take the spline where it refilled their copies better than the fill is expected
    #: to do on the gap (:func:`_with_spline_joined`), its error on the copies taken this many times
    #: over: that tail (chosen on the tuning takes, docs/DESIGN.md: as many gains, fewer losses than
    #: at 1)
    spline_tail: float = 2.0
    #: where more than this share of the points is gone on the mean over a gap, an estimate of it is
    #: taken to be off by at least its RMS distance from the spline through the take less
    #: ``off_spline`` times the spline's expected RMS error, whatever its copies said
    #: (:func:`_off_the_spline`; chosen on the tuning takes, docs/DESIGN.md: 0.3 and 0.7 gave the
    #: same; at 1 time the spline's error the gains were the same, the losses larger)
    body_gone: float = 0.5
    off_spline: float = 2.0
    #: there, a short gap's fill is expected to err this many times (squared) what its copies said,
    #: where more of the body was seen (:func:`_with_spline`; chosen on the tuning takes,
    #: docs/DESIGN.md: 2, 4, 8 and leaving the fill out gained 0.6-1.2 %, the losses growing with
    #: it)
    gone_doubt: float = 4.0
    #: the smooth track through the take that all of the above weigh (the spline) goes this share of
    #: the way on to the take's own interpolator (:func:`~.baselines.fill_learned`: the take's
    #: windows of each gap's length say how its points move on from their keys; chosen on the tuning
    #: takes, docs/DESIGN.md: the whole way gained as much on the mean and lost more on some takes)
    learned: float = 0.5
    #: ... on gaps of up to this many seconds (the longest the tuning takes' bursts had)
    learned_seconds: float = 0.5
    #: where nearly all of the body is gone at once - more than ``all_gone`` of the points on the
    #: mean over a marker's gap longer than ``spline_seconds`` and of up to ``learned_seconds``,
    #: both ends in the take - its fill goes ``all_gone_share`` of the way on to the take's own
    #: interpolator: the few partners and the models that see a few points stray further than their
    #: copies foretell (chosen on the tuning takes, docs/DESIGN.md)
    all_gone: float = 0.9
    all_gone_share: float = 0.5
    #: beside the partner's pattern, a marker's short gap at a clip end joins the take's own
    #: interpolator from its one key (:func:`~.baselines.fill_learned_ends`) by its inverse error on
    #: one-sided copies times this weight (chosen on the tuning takes, docs/DESIGN.md: at weight 1
    #: more gain, a larger worst case; a skeleton's joints lost by it)
    learned_ends_weight: float = 0.5
    #: and only on gaps of up to this many seconds (on the tuning takes it gained on every take at
    #: 0.025 and 0.05 s, and lost on some at 0.1 s)
    learned_ends_seconds: float = 0.05
    #: a marker's place among its rigid partners (:func:`~.regression.regress_in_frame`) fills a gap
    #: at a clip's end, from its one end, only if it lasts this many seconds or more (shorter ones
    #: went astray on the tuning takes, where the partner's pattern carries them: docs/DESIGN.md)
    place_ends_seconds: float = 0.1
    spline_copies: int = 4
    spline_margin: int = 10
    spline_reach: int = 4
    #: beside the spline, the pattern fill (the steadiest partner's trajectory, offset to the gap's
    #: ends: it follows a turn inside the gap that the spline cuts) joins short gaps by its inverse
    #: error on the same copies at this weight (docs/DESIGN.md)
    pattern_weight: float = 0.5
    #: longer gaps lean towards the same spline near their ends (:func:`_with_spline_ends`), by a
    #: weight per distance from the nearer end: the least-squares share of the copies' frames at
    #: that distance (shrunk towards none by this ridge), never rising with the distance, none below
    #: ``ends_least`` or where fewer than ``ends_samples`` copied frames lie that far in
    ends_ridge: float = 0.5
    ends_least: float = 0.1
    ends_samples: int = 20
    #: the knowledge base's fill of the copies only weighs the methods: it fits fewer local models
    #: (at most this many a second), stops after fewer iterations than the fill of the gaps and
    #: takes this query-noise factor (the one ``KnnSettings.unchecked_factor`` uses where nothing
    #: can be checked) instead of choosing one (same accuracy on the tuning takes, 0.8-0.9x the
    #: time: docs/DESIGN.md)
    copies_model_fps: float = 15.0
    copies_iterations: int = 10
    copies_query_noise: float = 0.25
    #: the take's own regressions (of a point on the rest of the body; a marker's place among its
    #: partners)
    regression: RegressionSettings = RegressionSettings()
    #: the windows of the knowledge base's motion (and of the take's own) on long gaps
    matching: MatchSettings = MatchSettings()

    def long_gap_seconds(self, with_kb):
        """How long a joint's gaps last on the mean for its long-gap estimates to join."""
        return self.match_seconds if with_kb else self.alone_seconds


@dataclass(frozen=True)
class GapAccount:
    """How ``auto`` filled one gap of a point (``fill(..., return_account=True)``).

    ``point``: its name; ``first``, ``last``: its frames (rows, inclusive). The shares of the
    estimates in its fill, as ``auto`` weighed them on the point's copies (they sum to 1):
    ``rigid`` (the rigid partners; on a marker set with the marker's place among them
    regressed, :func:`~.regression.regress_in_frame`), ``models`` (the knowledge base's local
    models), ``windows``
    (the knowledge base's windows of motion), ``own`` (the take's own regression on the rest of
    the body), ``spline`` (a spline through the take, short gaps; half of the way on to the
    take's own interpolator there, :func:`_smooth_of`, and at a marker's clip end that
    interpolator from the one key, :func:`~.baselines.fill_learned_ends`, and where nearly all
    of the body is gone, that interpolator, :func:`_with_all_gone_learnt`), ``pattern`` (a
    partner's pattern: short gaps, and a point's long gaps within the knowledge base's side); on
    a marker set the rigid partners' share is their mean over the gap's frames
    (:func:`_by_steadiness`). Where an estimate has no value at some frame (no rigid donors
    there) the others fill it alone.
    ``estimate``: the fill's RMS error in metres on copies of the point's gaps (the point hidden
    where it is observed, refilled as the gaps were), its rigid part scaled to how far the rigid
    donors spread over this gap (:func:`_harder_for_partners`), and where most of the body is
    gone raised to how far the fill strays from a spline through the take
    (:func:`_off_the_spline`): what ``auto`` expects here, not a measurement of the gap; NaN
    where the point had no copies."""

    point: str
    first: int
    last: int
    rigid: float
    models: float
    windows: float
    own: float
    spline: float
    pattern: float = 0.0
    estimate: float = float("nan")

    def summary(self):
        """``LTOE 1861-1920 ~57 mm``: the point, its frames counted from 1, the estimate."""
        return (f"{self.point} {self.first + 1}-{self.last + 1} "
                + (f"~{1000 * self.estimate:.0f} mm" if np.isfinite(self.estimate) else
                   "(no copies)"))


#: gaps (or takes) named to review first: the largest errors their copies expect
#: (:func:`worst_first`; ``fill``, ``batch``'s report and command, the demo)
REVIEW_FIRST = 3


def worst_first(accounts):
    """The gaps' accounts that have an estimate, the largest first: the order to review them."""
    return sorted((a for a in accounts if np.isfinite(a.estimate)), key=lambda a: -a.estimate)


def kb_for_take(names, method, kb=None, alone=TAKE_ALONE, choose="-k KB.npz"):
    """``(kb, note)``: the knowledge base a fill by ``method`` of a take with point or bone
    ``names`` uses, and a line for the user where none was chosen. ``kb`` where given, None for
    methods that use none; else the starter knowledge base that fits the names
    (:func:`~.kb.starter_kb`), or where none fits None for ``auto`` (it fills from the take
    alone, the note says so, ending with ``alone``), a :class:`GapFillError` for the methods
    that need one (``choose``: how to give one)."""
    if kb is not None or method not in USES_KB:
        return kb, None
    try:
        path, kb = starter_kb(names_for_kb(names))
    except GapFillError as exc:
        if method in NEEDS_KB:
            raise GapFillError(f"method {method!r} needs a knowledge base ({choose}); {exc}; "
                               "without one, 'auto' fills from the take alone") from None
        return None, f"{exc}; until then, {alone}"
    return kb, f"the starter knowledge base {path.name} ({kb.size} poses of CMU motion)"


def fill(motion, method=DEFAULT_METHOD, kb=None, settings=None, progress=None, should_cancel=None,
         report=None, max_gap=None, return_account=False, trace=None, config=None):
    """Fill the gaps of a motion with the named method.

    Parameters
    ----------
    motion : Motion
    method : str
        One of :data:`METHODS`; ``knn`` (the knowledge-base method) is the default.
    kb : KnowledgeBase, optional
        Needed by ``knn`` and ``pca``.
    settings : KnnSettings, optional
        ``knn`` settings (K, weights, ...).

    max_gap : int, optional
        Gaps longer than this many frames are left unfilled.
    return_account : bool
        Also return how ``auto`` filled each gap.
    report, trace : callable, optional
        ``report(message)``: what the user is told (points left unfilled, ...); ``trace``: what
        each of ``auto``'s stages did (``--verbose``).
    config : AutoConfig, optional
        What ``auto`` goes by (default: ``AutoConfig()``).

    Returns
    -------
    Motion
        Observed samples unchanged, missing ones filled and flagged in ``filled``.
    list of GapAccount or None
        With ``return_account``: for ``auto``, per gap it filled (run of missing frames of a
        point, in point order; not those ``max_gap`` left out or no estimate could place) its
        :class:`GapAccount`; None for the other methods.
    """
    if method not in METHODS:
        raise GapFillError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    if method in NEEDS_KB and kb is None:
        raise GapFillError(f"method {method!r} needs a knowledge base (-k KB.npz); without "
                           "one, 'auto' fills from the take alone")
    if not motion.missing.any():
        return (motion, [] if method == "auto" else None) if return_account else motion
    groups = performers(motion.names) if motion.parents is None else {}
    if groups:
        return _fill_performers(motion, groups, method, kb, settings, progress, should_cancel,
                                report, max_gap, return_account, trace, config)
    accounts = None
    if method == "auto":
        out, accounts = _fill_auto(motion, kb, settings, progress, should_cancel, report,
                                   trace, config or AutoConfig())
    else:
        out = _fill(motion, method, kb, settings, progress, should_cancel, report)
    if max_gap:
        kept = np.zeros(motion.missing.shape, dtype=bool)
        for p, a, b in motion.gap_runs():
            kept[a:b + 1, p] = b - a + 1 > max_gap
        out = out.replace(positions=np.where(kept[..., None], np.nan, out.positions),
                          filled=out.filled & ~kept if out.filled is not None else None)
    if accounts is not None:
        index = {name: p for p, name in enumerate(motion.names)}
        accounts = [a for a in accounts
                    if not out.missing[a.first:a.last + 1, index[a.point]].all()]
    return (out, accounts) if return_account else out


def _fill_performers(motion, groups, method, kb, settings, progress, should_cancel, report,
                     max_gap, return_account, trace, config):
    """:func:`fill` of a take of several performers (:func:`~.performers.performers`): each
    on its own, by the names without its prefix; a performer the knowledge base does not fit
    fills from its take alone (``auto``) or is left as it is (the methods that need one)."""
    positions, filled = motion.positions.copy(), np.zeros(motion.missing.shape, bool)
    accounts = []
    for n, (prefix, members) in enumerate(groups.items()):
        names = [motion.names[i] for i in members]
        part = motion.select(names)
        part = part.replace(names=tuple(bare(name) for name in names))
        said = (lambda m, who=prefix or "unnamed points": report(f"{who}: {m}")) if report else None
        fits = kb
        if kb is not None:
            try:
                match_names(kb, part.names)
            except GapFillError as exc:
                fits = None
                if method in NEEDS_KB:
                    if said:
                        said(f"left unfilled: {exc}")
                    continue
        step = (lambda f, m, n=n: progress((n + f) / len(groups), m)) if progress else None
        out, mine = fill(part, method, kb=fits, settings=settings, progress=step,
                         should_cancel=should_cancel, report=said, max_gap=max_gap,
                         return_account=True, trace=trace, config=config)
        positions[:, members] = out.positions
        filled[:, members] = out.filled if out.filled is not None else False
        accounts += [replace(a, point=names[part.names.index(a.point)]) for a in mine or []]
    out = motion.replace(positions=positions, filled=filled)
    if not return_account:
        return out
    return out, (accounts if method == "auto" else None)


def _fill(motion, method, kb, settings, progress, should_cancel, report):
    if method == "knn":
        from .recover import KnnSettings, fill_knn  # scipy.optimize only when needed

        lacking = match_names(kb, motion.names)[1]
        if lacking and report:
            report(f"not in the knowledge base, left unfilled: {', '.join(lacking)}")
        return fill_knn(motion, kb, settings or KnnSettings(), progress=progress,
                        should_cancel=should_cancel, report=report)
    if method == "pca":
        common, _ = match_names(kb, motion.names)
        sub = motion.select(common)
        kb_cols = [kb.names.index(n) for n in common]
        done = baselines.fill_global_pca(sub.positions, kb.poses[:, kb_cols],
                                         kb.reference_for(common))
        index = [motion.names.index(n) for n in common]
    elif method == "local-spline":
        from .normalize import find_reference

        done = baselines.fill_local_spline(motion.positions, find_reference(motion.names))
        index = list(range(motion.n_points))
    else:
        func = {"linear": baselines.fill_linear, "spline": baselines.fill_spline,
                "rigid": baselines.fill_rigid, "pattern": baselines.fill_pattern,
                "svt": baselines.fill_svt, "intercorrelation": baselines.fill_intercorrelation}
        done = func[method](motion.positions)
        index = list(range(motion.n_points))
    out = motion.positions.copy()
    out[:, index] = done
    return _with_fill(motion, out)


def _with_fill(motion, out):
    """``motion`` with its missing samples taken from ``out`` and flagged as filled."""
    missing = motion.missing
    out = np.where(missing[..., None], out, motion.positions)
    filled = missing & ~np.isnan(out[..., 0])
    if motion.filled is not None:
        filled |= motion.filled
    return motion.replace(positions=out, filled=filled)


def _fill_auto(motion, kb, settings, progress, should_cancel, report, trace, cfg):
    """The knowledge-base fill and a rigid-body fill, blended per point by how well each refills
    copies of the point's gaps on this take, then held to what the take keeps.

    Each gap is copied (same point, same length, or shorter where the take has no room) to
    nearby frames where its point is observed (:func:`validation_gaps`), and every estimate
    refills the copies as it will the gaps (:func:`_copies_refilled`; where rigid partners carry
    a point closely through a gap, the knowledge base sees it there and at its copies). A
    point's gaps take the knowledge base and the rigid partners by inverse errors on its copies
    (:func:`_weighed`; on long gaps the knowledge base's estimate joined by its windows of
    motion, the take's own regression and a partner's pattern, :func:`_with_long_gap_estimates`;
    on a marker set its share follows the partners' spread per frame, :func:`_by_steadiness`,
    and leaves the models out where most of the body is gone). The smooth track through the
    take then joins by its errors on the copies (:func:`_with_smooth_track`), nearly-all-gone
    gaps go part of the way on to the take's own interpolator, holes no estimate reached take
    the spline, and the fill is moved onto the distances the take keeps
    (:func:`_with_distances_kept`). Returns the filled motion and a :class:`GapAccount` per gap
    (:func:`_accounts`)."""
    from .recover import KnnSettings

    report = report or (lambda message: None)
    trace = trace or (lambda message: None)  # what each stage did, for --verbose
    progress = progress or (lambda fraction, message: None)
    settings = settings or KnnSettings()
    # without a knowledge base the take alone fills: rigid partners, a spline, a partner's pattern
    lacking = list(motion.names) if kb is None else match_names(kb, motion.names)[1]
    missing = motion.missing
    probe = validation_gaps(missing, cfg.probes,
                            least=0 if motion.parents is None else cfg.probe_frames,
                            enough=cfg.probe_frames)
    seconds = cfg.long_gap_seconds(kb is not None)
    with np.errstate(invalid="ignore"):
        long = (probe.any(axis=0) & (_mean_run(missing) >= seconds * motion.fps)
                & (motion.parents is not None))

    donors = {}  # the pattern's, on the take with its copies hidden
    # marker sets let partners carry a marker alone within more
    alone = cfg.rigid_first_markers if motion.parents is None else cfg.rigid_first
    partners = _Partners(motion, should_cancel, cfg)
    rigid, spread = partners.carried(motion)
    # the copies are refilled as the gaps will be: where rigid partners carry a point closely
    # through a gap, the knowledge base sees it there (below), so it is seen at the copies too
    hidden = motion.replace(positions=np.where(
        probe[..., None], np.nan,
        np.where(_carried_closely(missing, spread, alone, motion.fps, cfg)[..., None], rigid,
                 motion.positions)))
    markers = motion.parents is None and probe.any()
    (knn_copies, (on_copies, copies_spread), (placed_copies, placed_gaps), matched, regressed,
     patterned) = _copies_refilled(hidden, motion, kb, probe, long, markers, partners, donors,
                                   settings, progress, should_cancel, cfg)
    per_sample = np.full(motion.n_points, np.nan)  # the fill's squared error on its copies
    eased = {}  # gaps blended with a spline (and pattern): their shares and the error expected

    def on_copies_of(out):
        return _on_copies(probe, motion.positions, out)

    # the knowledge base's share per point, and within its estimate the windows', the take's
    # regression's and the partner's pattern's; the errors on the copies of both sides
    weight, (windows, own, by_partner), e_kb, e_rigid, on_copies, rigid = _weighed(
        motion, probe, kb, long, alone, spread, on_copies_of, knn_copies,
        (on_copies, rigid, placed_copies, placed_gaps, matched, regressed, patterned), donors,
        trace, cfg)
    # the knowledge base has none of them: rigid partners carry them, or on long gaps the take's
    # own regression and a partner's pattern stand in for it (without a knowledge base too)
    weight[[p for p in map(motion.names.index, lacking) if own[p] == 0]] = 0.0
    start = 0.5 if probe.any() else 0.0  # of the progress: the copies' fill came first
    knn = _kb_estimate(motion, rigid, weight, kb, long, (windows, own, by_partner), settings,
                       lambda f, m: progress(start + 0.5 * f, m), should_cancel, report, trace,
                       cfg)
    # the rigid donors' squared spread at each frame and on the mean of each point's copies
    spreads = _squared_spreads(probe, spread, copies_spread)
    harder = _harder_for_partners(*spreads)
    # the knowledge base's share per frame: on a marker set it follows the rigid donors' spread
    shares = np.broadcast_to(weight, missing.shape)
    if markers:
        shares = _by_steadiness(weight, e_kb, e_rigid, *spreads)
    if motion.parents is None and kb is not None:
        shares, knn = _models_left_out_where_gone(missing, shares, knn, cfg)
    out = _blend(knn, rigid, shares)
    if probe.any():
        if long.any():
            knn_copies = _mix_in(_mix_in(_mix_in(knn_copies, matched, windows), regressed, own),
                                 patterned, by_partner)
        copies = _blend(knn_copies, on_copies, weight)
        out, eased, per_sample = _with_smooth_track(motion, out, probe, copies, weight, shares,
                                                    harder, partners.carried, on_copies_of,
                                                    trace, cfg)
    out, all_gone = _with_all_gone_learnt(motion, out, trace, cfg)
    out, holes = _with_holes_splined(motion, out, trace, cfg)
    eased.update({(p, a): (1.0, 0.0, float("nan")) for p, a in holes})
    if kb is not None:
        trace(_rigidly_line(motion, weight))
    if lacking:
        report(_lacking_line(motion, out, lacking, kb is None))
    accounts, uncertainty, hold = _accounts(motion, shares, eased, all_gone, per_sample, harder,
                                            (windows, own, by_partner), cfg)
    out = _with_distances_kept(motion, out, uncertainty, hold, trace, partners.cache, cfg)
    return _with_fill(motion, out), accounts


class _Partners:
    """A take's rigid partners, their statistics computed once (``cache``): ``carried`` (the
    rigid-body estimate of a target's missing points from ``donors`` partners; marker sets reach
    past the gap ends, ``reach``) and ``placed`` (a marker's place among its partners,
    regressed on further ones); both stop once ``stop`` is set or the user cancels."""

    def __init__(self, motion, should_cancel, cfg):
        import threading

        self.motion, self.should_cancel, self.cfg = motion, should_cancel, cfg
        self.cache = {}
        self.reach = cfg.reach if motion.parents is None else None
        self.stop = threading.Event()  # the fill ended early: the estimates beside it stop too

    def stopped(self):
        return self.stop.is_set() or bool(self.should_cancel and self.should_cancel())

    def carried(self, target, only=None):
        from .baselines import rigid_estimates

        rigid, spread = rigid_estimates(target.positions, self.cfg.donors, weighted=True,
                                        partners=self.motion.positions, cache=self.cache,
                                        reach=self.reach, should_cancel=self.stopped, only=only)
        return np.where(np.isnan(spread)[..., None], np.nan, rigid), spread

    def placed(self, target, only=None):
        from .baselines import steady_partners
        from .regression import regress_in_frame

        return regress_in_frame(
            target.positions, lambda p: steady_partners(self.motion.positions, p, self.cache),
            only, round(self.cfg.place_ends_seconds * self.motion.fps), self.cfg.regression)


def _copies_refilled(hidden, motion, kb, probe, long, markers, partners, donors, settings,
                     progress, should_cancel, cfg):
    """The copies (``probe``, hidden in ``hidden``) refilled by each estimate: the knowledge
    base's models in one cheaper pass (its only use is to weigh the methods; ``copies_*``),
    and beside it, in a thread (numpy lets go of the interpreter in its products; the results
    are the same as one after the other), the rigid partners (:class:`_Partners`), on a marker
    set the place among them (of the gaps too), and on ``long`` gaps the windows of motion, the
    take's own regression and a partner's pattern; where the fill ends early, the estimates
    beside it stop too. Returns ``(knn, (rigid, spread), (placed_copies, placed_gaps), windows,
    regressed, pattern)``."""
    from concurrent.futures import ThreadPoolExecutor
    from dataclasses import replace

    from .matching import fill_match
    from .recover import fill_knn
    from .regression import regress_points

    with ThreadPoolExecutor(max_workers=1) as pool:
        carried, placed = partners.carried, partners.placed
        estimates = pool.submit(lambda: (carried(hidden) if probe.any() else (None, None),
                                         (placed(hidden, probe), placed(motion)) if markers
                                         else (None, None),
                                         fill_match(hidden, kb, long, partners.stopped,
                                                    cfg.matching).positions
                                         if long.any() and kb is not None else None,
                                         regress_points(hidden.positions, motion.names,
                                                        probe & long[None], cfg.regression)
                                         if long.any() else None,
                                         baselines.fill_pattern(hidden.positions,
                                                                only=probe & long[None],
                                                                cache=donors)
                                         if long.any() else None))
        try:
            scout = replace(settings, renormalise=False, max_iterations=min(
                settings.max_iterations, cfg.copies_iterations), model_fps=min(
                settings.model_fps or np.inf, cfg.copies_model_fps),
                query_noise=cfg.copies_query_noise if settings.query_noise == "auto"
                else settings.query_noise)
            knn_copies = (None if not probe.any() else
                          np.full(motion.positions.shape, np.nan) if kb is None else
                          fill_knn(hidden, kb, scout, progress=lambda f, m: progress(0.5 * f, m),
                                   should_cancel=should_cancel).positions)
        except BaseException:
            partners.stop.set()  # cancelled or failed: the estimates stop at their next gap
            raise
        return (knn_copies, *estimates.result())


def _with_smooth_track(motion, out, probe, copies, weight, shares, harder, carried, on_copies_of,
                       trace, cfg):
    """``out`` with the smooth track through the take (a spline, part of the way on to the
    take's own interpolator: :func:`_smooth_of`, :func:`_learnt`) weighed in by its errors on
    the copies (``copies``: the fill of them): longer gaps join it where it refilled them
    better than the fill is expected to do (:func:`_with_spline_joined`) and lean to it near
    their ends (:func:`_with_spline_ends`); short gaps are blended with it and a partner's
    pattern (:func:`_with_spline`), those at a clip end from their one key
    (:func:`_with_pattern_ends`; ``carried``: the rigid partners' estimate). Returns ``(out,
    eased, per_sample)``: the gaps it eased (their shares and the error expected) and the
    fill's squared error per copied sample of each point."""
    smooth = _smooth_of(motion, cfg)
    learnt, learnt_copies = _learnt(motion.missing, probe, motion.fps, cfg)
    spline = smooth(motion.positions, learnt)
    # the spline with the copies hidden, for the longer gaps (none: a take of short dropouts)
    hidden_spline = (smooth(np.where(probe[..., None], np.nan, motion.positions),
                            learnt_copies)
                     if _longer_gaps(motion.missing, motion.fps, cfg) else None)
    with np.errstate(invalid="ignore", divide="ignore"):  # points without copies: nan
        per_sample = on_copies_of(copies) / probe.sum(axis=0)

    def harder_at(p, a, b):  # how much harder than its copies a gap is for the fill
        return harder(p, a, b, float(shares[a:b + 1, p].mean()))

    out, eased = _with_spline_joined(motion, out, copies, probe, spline, hidden_spline,
                                     harder_at, trace, cfg)
    out = _with_spline_ends(motion, out, copies, probe, spline, hidden_spline, weight == 0,
                            trace, cfg)

    def rigid_of(hidden):
        return carried(motion.replace(positions=np.where(
            hidden[..., None], np.nan, motion.positions)), hidden)[0]

    out, short = _with_spline(motion, out, spline, per_sample, weight == 0, rigid_of, trace,
                              cfg)
    eased.update(short)
    out, at_ends = _with_pattern_ends(motion, out, per_sample, weight == 0, rigid_of, trace,
                                      cfg)
    eased.update(at_ends)
    return out, eased, per_sample


def _kb_estimate(motion, rigid, weight, kb, long, parts, settings, progress, should_cancel,
                 report, trace, cfg):
    """The knowledge base's fill of the gaps (NaN without one), seeing the points the rigid
    partners carry alone (``weight`` 0) as observed (they are never another point's donors: an
    estimate carried on would add its error to the next); on ``long`` gaps joined by its
    windows, the take's own regression and a partner's pattern at the shares ``parts``."""
    from .recover import fill_knn

    ahead = (weight == 0)[None] & ~np.isnan(rigid[..., 0])
    given = motion.replace(positions=np.where(ahead[..., None], rigid, motion.positions))
    # (the points it lacks are named later, with what became of them)
    knn = np.full(motion.positions.shape, np.nan) if kb is None else fill_knn(
        given, kb, settings, progress=progress, should_cancel=should_cancel,
        report=report).positions
    if long.any():
        knn = _with_long_gap_estimates(knn, given, motion.missing, kb, long, parts,
                                       should_cancel, trace, cfg)
    return knn


def _with_long_gap_estimates(knn, given, missing, kb, long, parts, should_cancel, trace, cfg):
    """The knowledge base's estimate ``knn`` of the points with ``long`` gaps joined, at the
    shares ``parts`` (per point), by its windows of motion, the take's own regression on the
    rest of the body and a partner's pattern, each made on the take as the knowledge base sees
    it (``given``: the points rigid partners carry alone included) for its gaps (``missing``)."""
    from .matching import fill_match
    from .regression import regress_points

    windows, own, by_partner = parts
    seconds = cfg.long_gap_seconds(kb is not None)
    if (windows > 0).any():
        # matched as on the copies, over every point with long gaps (the stretches and the
        # take's own windows a point gets depend on which others are matched with it)
        knn = _mix_in(knn, fill_match(given, kb, long, should_cancel, cfg.matching).positions,
                      windows)
        trace(f"auto: windows of the knowledge base's motion join its models on "
               f"{int((windows > 0).sum())} points with gaps of {seconds:g} s or more")
    if (own > 0).any():
        # on the rest of the body as the knowledge base sees it (the points rigid partners carry
        # alone included), as the copies' regression saw it
        knn = _mix_in(knn, regress_points(given.positions, given.names,
                                          missing & (own > 0)[None], cfg.regression), own)
        trace(f"auto: the take's own regression on the rest of the body joins on "
               f"{int((own > 0).sum())} points with gaps of {seconds:g} s or more")
    if (by_partner > 0).any():
        knn = _mix_in(knn, baselines.fill_pattern(
            given.positions, only=missing & (by_partner > 0)[None]), by_partner)
        trace(f"auto: a partner's pattern joins the knowledge base's estimate on "
               f"{int((by_partner > 0).sum())} points with gaps of {seconds:g} s or "
               f"more")
    return knn


def _on_copies(probe, truth, out):
    """Per point, the squared error of ``out`` against ``truth`` summed over its copies
    (``probe``; a method that left some copy unfilled: inf, not weighed against the other)."""
    error = np.where(probe, np.sum((out - truth) ** 2, axis=2), 0).sum(axis=0)
    return np.nan_to_num(error, nan=np.inf)


def _weighed(motion, probe, kb, long, alone, spread, on_copies_of, knn_copies, estimates, donors,
             trace, cfg):
    """Per point, the knowledge base's share against the rigid partners' by their errors on the
    point's copies (inverse-variance weights; the rigid error no lower than its donors' spread
    allows, :func:`_spread_floor`; points the partners refill within ``alone`` theirs alone),
    and within the knowledge base's estimate on long gaps the shares of its windows, the take's
    own regression and a partner's pattern (each joining where it refilled the copies better,
    :func:`_joined`). On a marker set the marker's place among its partners joins the rigid
    estimate first. ``estimates``: the rigid partners' on the copies and the gaps, the place's
    on both, the windows', the regression's and the pattern's on the copies. Returns
    ``(weight, (windows, own, by_partner), e_kb, e_rigid, rigid_copies, rigid)``."""
    on_copies, rigid, placed_copies, placed_gaps, matched, regressed, patterned = estimates
    missing, markers = motion.missing, motion.parents is None
    weight = np.ones(motion.n_points)
    windows, own, by_partner = (np.zeros(motion.n_points) for _ in range(3))
    if not probe.any():  # nothing to weigh by: the knowledge base's where it has the point
        return weight, (windows, own, by_partner), None, None, on_copies, rigid
    e_knn, e_rigid = on_copies_of(knn_copies), on_copies_of(on_copies)
    e_rigid = np.maximum(e_rigid, _spread_floor(missing, probe, spread, cfg))
    if markers:  # the place among the partners joins the rigid estimate by its error
        among = _joined(e_rigid, _on_copies_where(probe, on_copies_of, placed_copies,
                                                  on_copies))[0]
        on_copies = _mix_in(on_copies, placed_copies, among)
        rigid = _mix_in(rigid, placed_gaps, among)
        if (among > 0).any():
            trace(f"auto: the place among its rigid partners, regressed on further "
                   f"partners, joins the rigid estimate on {int((among > 0).sum())} of "
                   f"{int(probe.any(axis=0).sum())} markers with copies")
    seen = probe.any(axis=0)
    e_kb = e_knn  # of the knowledge base's estimate: the models, with the windows on long gaps
    if long.any():
        # the windows join where they refilled the point's copies better than the models
        if kb is not None:
            windows, e_kb = _joined(e_knn, np.where(long, on_copies_of(matched), np.inf),
                                    cfg.join_ramp)
        # the take's own regression joins the knowledge base's estimate by its error
        own, e_kb = _joined(e_kb, np.where(long, on_copies_of(regressed), np.inf))
        # the partner's pattern where it refilled them better still, trusted no closer than
        # its offset wanders over the take
        e_pattern = np.maximum(on_copies_of(patterned), cfg.pattern_floor * probe.sum(
            axis=0) * _offset_variance(missing, donors))
        by_partner, e_kb = _joined(e_kb, np.where(long, e_pattern, np.inf), cfg.join_ramp)
    with np.errstate(invalid="ignore"):
        share = e_rigid / (e_kb + e_rigid)
    weight[seen] = np.where(np.isfinite(share[seen]), share[seen],
                            np.isfinite(e_knn[seen]).astype(float))
    # points their rigid partners carry alone
    first = seen & (e_rigid < e_knn) & (e_rigid < alone ** 2 * probe.sum(axis=0))
    weight[first] = 0.0
    return weight, (windows, own, by_partner), e_kb, e_rigid, on_copies, rigid


def _accounts(motion, shares, eased, all_gone, per_sample, harder, parts, cfg):
    """Per gap its :class:`GapAccount` (the estimates' shares: the knowledge base's side
    ``shares`` split by ``parts``, the windows', the take's regression's and the pattern's share
    of it per point; the spline's and pattern's from ``eased``; grown where nearly all of the
    body is gone, ``all_gone``) and its squared error expected (``per_sample`` scaled by
    ``harder``); the samples each gap expects to err by, and those held in place when the
    distances are kept (a marker's short gaps, where the spline and a partner's pattern come
    closer than a few millimetres of sliding skin). Returns ``(accounts, uncertainty, hold)``."""
    accounts = []
    windows, own, by_partner = parts
    missing = motion.missing
    uncertainty = np.zeros(missing.shape)  # each gap's squared error expected
    # a marker's short gaps, where the spline and a partner's pattern come closer than a few
    # millimetres of sliding skin, hold their place when the distances are kept
    hold = np.zeros(missing.shape, bool)
    for p, a, b in gap_runs(missing):
        kb_side = float(shares[a:b + 1, p].mean())
        spline_share, pattern_share, squared = eased.get(
            (p, a), (0.0, 0.0, per_sample[p] * harder(p, a, b, kb_side)))
        if (p, a) in all_gone:  # the smooth track's share grows by the rest's part
            spline_share += cfg.all_gone_share * (1 - spline_share)
            pattern_share *= 1 - cfg.all_gone_share
        hold[a:b + 1, p] = motion.parents is None and b - a < _spline_frames(motion.fps, cfg)
        # (a held sample counts as known and sure where the others' fallback is taken)
        uncertainty[a:b + 1, p] = 0.0 if hold[a, p] else squared
        rest = 1 - spline_share - pattern_share
        kb_share = kb_side * rest
        models = kb_share * (1 - by_partner[p])  # the models, the windows and the regression
        accounts.append(GapAccount(
            motion.names[p], a, b, rigid=float((1 - kb_side) * rest),
            models=float(models * (1 - windows[p]) * (1 - own[p])),
            windows=float(models * windows[p] * (1 - own[p])), own=float(models * own[p]),
            spline=float(spline_share), pattern=float(pattern_share + kb_share * by_partner[p]),
            estimate=float(np.sqrt(squared)) if np.isfinite(squared) else float("nan")))
    return accounts, uncertainty, hold


def _with_distances_kept(motion, out, uncertainty, hold, report, partners, cfg):
    """The fill ``out`` with the take's missing samples moved onto the distances it keeps
    exactly (a skeleton) or towards those it keeps within ``kept_spread`` (a marker
    set, each pair as far as its spread lets it, ``kept_seen`` times as loosely where
    one of its ends is seen, and aiming ``kept_local`` of the way from its mean
    distance to its own about the gap; :func:`~.baselines.steady_pairs`,
    :func:`~.distances.keep_distances`), each by its expected squared error ``uncertainty``
    (where unknown: the largest known, else 1 m^2; at least :data:`~.baselines.RIGID_TIE`
    squared); the samples of ``hold`` (a marker's short gaps) keep their place. The gaps'
    estimates stay those of the fill before: moved alike, the copies (more points hidden at
    once) judged the move worse than it is on the gaps (docs/DESIGN.md).
    ``partners``: the rigid fill's statistics of the take (:func:`~.baselines.steady_partners`),
    where its pairs' spreads may be kept already."""
    from .distances import keep_distances

    missing = motion.missing
    markers = motion.parents is None  # a skeleton's bones are exact; markers slide on the skin
    pairs, lengths, spreads = baselines.steady_pairs(
        motion.positions, cfg.kept_spread if markers else baselines.RIGID_TIE, partners)
    if not (missing[:, pairs[:, 0]] | missing[:, pairs[:, 1]]).any():
        return out
    # the fill holds estimates of the missing samples alone where the knowledge base gave none:
    # the seen ends of the pairs are where the take saw them
    out = np.where(missing[..., None], out, motion.positions)
    known = np.isfinite(uncertainty) & missing
    fallback = uncertainty[known].max() if known.any() else 1.0
    # no filled sample that moves is surer of its place than the rounding of a rigid tie
    uncertainty = np.where(missing & ~hold, np.maximum(np.where(known, uncertainty, fallback),
                                                       baselines.RIGID_TIE ** 2), 0.0)
    kept = keep_distances(out, missing, uncertainty, pairs, lengths,
                          spreads if markers else None, local=cfg.kept_local if markers else 0.0,
                          seen=cfg.kept_seen if markers else 1.0)
    moved = np.linalg.norm(kept - out, axis=2)[missing]
    moved = moved[np.isfinite(moved)]
    if moved.size:
        report(f"auto: filled samples moved towards the {len(pairs)} distances the take keeps"
               + (f" within {1000 * cfg.kept_spread:g} mm (markers on one segment; each "
                  f"{cfg.kept_local:.0%} of the way to its own distance about the gap)" if markers
                  else " exactly (a bone's length, joints on one segment)")
               + f": median {1000 * np.median(moved):.1f} mm, at most "
               f"{1000 * moved.max():.1f} mm")
    return kept


def _rigidly_line(motion, weight):
    """``auto``'s trace of the gapped points rigid partners carry more than the knowledge base."""
    gappy = motion.missing.any(axis=0)
    rigidly = gappy & (weight < 0.5)
    return (f"auto: rigid partners carry {int(rigidly.sum())} of {int(gappy.sum())} gapped "
            f"points more than the knowledge base"
            + (f" ({', '.join(motion.names[p] for p in np.flatnonzero(rigidly)[:8])}"
               f"{'...' if rigidly.sum() > 8 else ''})" if rigidly.any() else ""))


def _lacking_line(motion, out, lacking, no_kb):
    """``auto``'s report on the points the knowledge base lacks (all, without one: ``no_kb``):
    which of their gaps the take alone (rigid partners, a spline, a partner's pattern) filled,
    and which it left."""
    fates = {"filled from the take alone": [], "partly filled": [], "left unfilled": []}
    for name in lacking:
        p = motion.names.index(name)
        gone = motion.missing[:, p]
        if gone.any():
            left = np.isnan(out[gone, p, 0])
            fates["left unfilled" if left.all() else "partly filled" if left.any()
                  else "filled from the take alone"].append(name)
    said = "; ".join(f"{fate}: {', '.join(names)}" for fate, names in fates.items() if names)
    if no_kb:
        return "no knowledge base: " + (said or "no gaps")
    return "points the knowledge base lacks: " + (said or f"{', '.join(lacking)} (no gaps)")


def _on_copies_where(probe, on_copies_of, estimate, otherwise):
    """Per point, an estimate's squared error on its copies, ``otherwise``'s at the copied
    samples it leaves unfilled, as the gaps will be; inf where it fills none of them."""
    filled = np.isfinite(estimate[..., 0])
    error = on_copies_of(np.where(filled[..., None], estimate, otherwise))
    return np.where((probe & filled).any(axis=0), error, np.inf)


def _harder_for_partners(squared, on_copies):
    """``harder(p, a, b, share)``: how much harder than its copies the gap ``a``-``b`` of point
    ``p`` is for the fill, as a factor of the copies' squared error: the rigid estimate's part
    of it (1 - ``share``, the knowledge base's share of the gap) scaled by its donors' mean
    squared spread over the gap (``squared``, per frame) against over the copies
    (``on_copies``, per point; both from :func:`_squared_spreads`; one of a point's gaps whose
    steadiest partners are out of sight too is filled worse than the copies foretell), the
    knowledge base's part as it is. Where either spread is unknown, 1. On the
    CMU marker tuning takes this ranked each take's gaps closer to how they came out (Spearman
    0.50-0.52 -> 0.56-0.60; docs/DESIGN.md)."""
    known = np.isfinite(squared)
    sums = np.vstack([np.zeros((1, squared.shape[1])), np.cumsum(np.where(known, squared, 0),
                                                                 axis=0)])
    counts = np.vstack([np.zeros((1, squared.shape[1])), np.cumsum(known, axis=0)])

    def harder(p, a, b, share):
        frames = counts[b + 1, p] - counts[a, p]
        if not frames or not on_copies[p] > 0:
            return 1.0
        ratio = (sums[b + 1, p] - sums[a, p]) / frames / on_copies[p]
        if not ratio > 0:
            return 1.0
        return (1 - share) * ratio + share

    return harder


def _squared_spreads(probe, spread, copies_spread):
    """The rigid donors' squared spread at each frame (``spread``: (frames, points), NaN where
    unknown) and each point's mean of it over its copies (``copies_spread`` at ``probe``; NaN
    where unknown), each with :data:`~.baselines.SPREAD_FLOOR` added in quadrature (a
    skeleton's copies carried by an exactly rigid segment have a spread of rounding alone)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        if copies_spread is None:
            on_copies = np.full(probe.shape[1], np.nan)
        else:
            at_copies = np.where(probe, copies_spread ** 2 + baselines.SPREAD_FLOOR ** 2, np.nan)
            on_copies = np.nansum(at_copies, axis=0) / np.sum(np.isfinite(at_copies), axis=0)
    return spread ** 2 + baselines.SPREAD_FLOOR ** 2, on_copies


def _by_steadiness(weight, e_kb, e_rigid, squared, on_copies):
    """Per frame (frames, points), the knowledge base's share of a marker set's points that
    ``weight`` (per point) blends with the rigid estimate: the copies' inverse-error weights
    with the rigid estimate's error on the copies (``e_rigid``; ``e_kb`` the knowledge base's)
    scaled at each frame by its donors' squared spread there (``squared``) against their mean
    over the copies (``on_copies``; both from :func:`_squared_spreads`): a marker's copies
    vouch for its rigid partners only as far as they stay as steady as at the copies (chosen on
    the CMU C3D tuning takes, docs/DESIGN.md; a skeleton's joints did worse
    with it). Points the partners carry alone, points the knowledge base alone fills
    and frames without a spread keep ``weight`` (a share strictly between 0 and 1 came from two
    finite errors)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        scaled = e_rigid[None] * squared / on_copies[None]
        share = scaled / (e_kb[None] + scaled)
    judged = (0 < weight) & (weight < 1)
    return np.where(judged[None] & np.isfinite(share), share, weight[None])


def _models_left_out_where_gone(missing, shares, knn, cfg):
    """The knowledge base's share per frame (``shares``) and estimate (``knn``) with both left
    out of each marker's gap where more than ``body_gone`` of the points are gone on the
    mean over it: its models see too little of the body there, and the gap is filled as a take
    without a knowledge base fills it (the rigid partners left, then the spline and the take's
    own interpolator; chosen on the CMU C3D tuning takes' bursts, docs/DESIGN.md)."""
    gone = [(p, a, b) for p, a, b in gap_runs(missing) if _body_gone(missing, a, b, cfg.body_gone)]
    if not gone:
        return shares, knn
    shares = np.array(np.broadcast_to(shares, missing.shape), dtype=float)
    knn = knn.copy()
    for p, a, b in gone:
        shares[a:b + 1, p] = 0.0
        knn[a:b + 1, p] = np.nan
    return shares, knn


def _mix_in(knn, other, share):
    """An estimate (the models' fill; the rigid estimate) with another mixed in at each point's
    ``share`` where the other has a value (the windows, :func:`~.matching.fill_match`; the
    take's own regression, :func:`~.regression.regress_points`; a marker's place among its
    partners, :func:`~.regression.regress_in_frame`); ``other`` None: none. At a share of 1
    the other alone, where ``knn`` has none (no knowledge base)."""
    if other is None:
        return knn
    part = np.where(np.isnan(other[..., :1]), 0.0, share[None, :, None])
    return np.where(part == 1, 0.0, knn) * (1 - part) + np.nan_to_num(other) * part


def _blend(kb, rigid, weight):
    """``weight`` (per point, or per frame and point) of the knowledge base's estimate and the
    rest of the rigid one; where one of them has none, the other alone."""
    w = np.broadcast_to(weight, kb.shape[:2]).copy()
    w[np.isnan(rigid[..., 0])] = 1.0
    w[np.isnan(kb[..., 0])] = 0.0
    out = np.where(np.isnan(kb), 0, kb) * w[..., None] + \
        np.where(np.isnan(rigid), 0, rigid) * (1 - w[..., None])
    out[np.isnan(kb[..., 0]) & np.isnan(rigid[..., 0])] = np.nan
    return out


def _longer_gaps(missing, fps, cfg):
    """The gaps ``(point, first, last)`` longer than ``spline_seconds`` with both ends in
    the take: those a spline through the take joins (:func:`_with_spline_joined`) and leans
    them towards near their ends (:func:`_with_spline_ends`)."""
    shortest = _spline_frames(fps, cfg)
    return [(p, a, b) for p, a, b in gap_runs(missing)
            if a > 0 and b < len(missing) - 1 and b - a + 1 > shortest]


def _with_spline_joined(motion, out, copies, probe, spline, hidden_spline, harder, report, cfg):
    """``out`` with each gap longer than ``spline_seconds`` (both ends in the take)
    joined by ``spline`` (a cubic spline of each point through the take) where that refilled the
    point's longer copies (``probe``) better than the fill is expected to do on the gap, by
    inverse errors (:func:`_joined`, ``join_ramp``): the spline's error on them
    (``hidden_spline``: the spline with the copies hidden) against the fill's (``copies``: its
    estimate of them; infinite where it left some open), the rigid part of that scaled by how
    far the rigid donors spread over the gap against over the copies (``harder(p, a, b)``,
    :func:`_harder_for_partners`), the spline's by ``spline_tail`` (over longer gaps
    its error has a tail that its copies do not foresee). Where most of the body is gone at
    once (a subject half out of the volume, a prop in the way) the donors left are far from the
    point and the knowledge base's models see few points: both stray by far more than the
    spline over a few tenths of a second. There (more than ``body_gone`` of the points
    gone on the mean over the gap) the spline is first joined by itself carried by how far its
    steadiest partners seen stray from their own splines over the gap
    (:func:`~.baselines.fill_spline_carried`: a landing or a turn the spline misses, the seen
    points miss too), by inverse errors on the same copies; that blend's error is not taken
    twice over, and it joins the fill by inverse errors without the ramp (the fill's copies,
    where more was seen, vouch for it more than the gap bears out). Returns the fill and, per
    gap joined (``(point, first frame)``), the spline's share (the carried one's in it), none of
    a pattern's and the blend's expected squared error per sample."""
    gaps = _longer_gaps(motion.missing, motion.fps, cfg)
    if not gaps:
        return out, {}
    shortest = _spline_frames(motion.fps, cfg)
    longer = np.zeros_like(probe)
    longest = np.zeros(probe.shape[1], dtype=int)
    for p, a, b in gap_runs(probe):
        longer[a:b + 1, p] = b - a + 1 > shortest
        longest[p] = max(longest[p], b - a + 1)
    with np.errstate(invalid="ignore", divide="ignore"):  # points without longer copies: nan
        def per_sample(estimate):
            error = np.sum((estimate - motion.positions) ** 2, axis=2)
            return np.where(longer, error, 0.0).sum(axis=0) / longer.sum(axis=0)

        e_fill, e_spline = per_sample(copies), per_sample(hidden_spline)
    # a fill that left some of its copies open is no rival to the spline
    e_fill[np.isnan(e_fill) & longer.any(axis=0)] = np.inf
    # where most of the body is gone, the spline carried by its partners' strays joins it
    # (chosen on the tuning takes, docs/DESIGN.md)
    gone = np.zeros_like(probe)
    for p, a, b in gaps:
        gone[a:b + 1, p] = _body_gone(motion.missing, a, b, cfg.body_gone)
    if gone.any():
        carried = baselines.fill_spline_carried(motion.positions, spline, gone)
        hidden = np.where(probe[..., None], np.nan, motion.positions)
        with np.errstate(invalid="ignore", divide="ignore"):
            e_carried = per_sample(baselines.fill_spline_carried(
                hidden, hidden_spline, longer & gone.any(axis=0)[None]))
        lean, e_lean = _joined(e_spline, e_carried)
    out, joined = out.copy(), {}
    for p, a, b in gaps:
        # copies shorter than the gap (a limb gone for half the take) do not show how a spline
        # strays over it
        if not (b - a + 1 <= longest[p] and not np.isnan(e_fill[p])
                and np.isfinite(e_spline[p])):
            continue
        smooth, e_other = spline[a:b + 1, p], e_spline[p] * cfg.spline_tail
        if gone[a, p] and lean[p] > 0:
            smooth = (1 - lean[p]) * smooth + lean[p] * carried[a:b + 1, p]
            e_other = e_lean[p]
        e_here = _off_the_spline(out, spline, motion.missing, p, a, b,
                                 e_fill[p] * harder(p, a, b), e_spline[p] * cfg.spline_tail, cfg)
        # where most of the body is gone the fill's copies vouch for it more than the gap bears
        # out (:func:`_off_the_spline`): the smooth estimate joins by inverse errors, unramped
        share, squared = _joined(np.array(e_here), np.array(e_other),
                                 None if gone[a, p] else cfg.join_ramp)
        if share > 0:  # where the fill has no value the spline alone
            here, there = out[a:b + 1, p], smooth
            out[a:b + 1, p] = np.where(np.isnan(here), there, (1 - share) * here + share * there)
            joined[p, a] = float(share), 0.0, float(squared)
    if joined:
        report(f"auto: a spline through the take joins {len(joined)} longer gaps where it "
               f"refilled their copies better than the fill is expected to do there (a mean "
               f"share of {np.mean([w for w, _, _ in joined.values()]):.0%})")
    return out, joined


def _with_spline_ends(motion, out, copies, probe, spline, hidden_spline, rigid_alone, report, cfg):
    """``out`` with the frames of its gaps longer than ``spline_seconds`` blended
    towards ``spline`` (a cubic spline of each point through the take; ``hidden_spline``: the
    same with the copies ``probe`` hidden) near their ends.

    Next to a gap's end a point carries on along a smooth curve: one frame in, the spline through
    the take misses by a millimetre or two, while the knowledge base's and the rigid estimates,
    which meet the observations only through an offset, jump by 10-20 mm there (and miss by more
    with every frame). The spline's error grows fast with the distance from the ends, so its
    share is a weight per distance class (:func:`~.stacking.classes`): the least-squares share
    of the spline against ``copies`` (the same estimate made for the copies ``probe`` of the
    gaps) on the copies' frames at that distance, ridge ``ends_ridge`` towards none,
    never rising with the distance, none below ``ends_least`` or where too few copied
    frames lie that far in. Points carried by their rigid partners alone (``rigid_alone``) and
    the others get weights of their own. Only gaps with both ends in the take, of points with a
    copy as long as the gap, take part: copies shorter than the gap (a limb gone for half the
    take) do not show how a spline strays over it."""
    from .stacking import DISTANCES, classes

    shortest = _spline_frames(motion.fps, cfg)
    gaps = _longer_gaps(motion.missing, motion.fps, cfg)
    if not gaps:  # e.g. a take of short dropouts only: no spline of the copies to make
        return out
    # per class of point and distance: spline-minus-estimate times error, its square, frames
    sums = np.zeros((3, 2, len(DISTANCES)))
    longest = np.zeros(motion.n_points, dtype=int)
    for p, a, b in gap_runs(probe):
        longest[p] = max(longest[p], b - a + 1)
        if b - a + 1 <= shortest:
            continue
        near, _ = classes(b - a + 1, motion.fps)
        lean = hidden_spline[a:b + 1, p] - copies[a:b + 1, p]
        error = motion.positions[a:b + 1, p] - copies[a:b + 1, p]
        ok = np.isfinite(lean).all(axis=1) & np.isfinite(error).all(axis=1)
        for k, value in enumerate(((lean * error).sum(axis=1), (lean * lean).sum(axis=1),
                                   np.ones(len(lean)))):
            np.add.at(sums[k, int(rigid_alone[p])], near[ok], value[ok])
    table = np.zeros((2, len(DISTANCES)))
    for c in range(2):
        product, square, frames = sums[:, c]
        enough = np.flatnonzero(frames >= cfg.ends_samples)
        if not len(enough):
            continue
        # classes nearer than any frame at this rate take the first one's weight; from the first
        # class after it without enough copied frames on, none
        short = np.flatnonzero((frames < cfg.ends_samples)
                               & (np.arange(len(frames)) > enough[0]))
        stop = short[0] if len(short) else len(frames)
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.clip(np.nan_to_num(product / (square * (1 + cfg.ends_ridge))), 0, 1)
        w[:enough[0]] = w[enough[0]]
        w[stop:] = 0.0
        w = np.minimum.accumulate(w)
        table[c] = np.where(w < cfg.ends_least, 0.0, w)
    out = out.copy()
    leaned = 0
    for p, a, b in gaps:
        if longest[p] < b - a + 1 or not table[int(rigid_alone[p])].any():
            continue
        near, _ = classes(b - a + 1, motion.fps)
        share = table[int(rigid_alone[p])][near][:, None]
        lean = spline[a:b + 1, p] - out[a:b + 1, p]
        out[a:b + 1, p] += np.where(np.isfinite(lean), share * lean, 0.0)
        leaned += 1
    if leaned:
        report(f"auto: {leaned} gaps lean towards a spline through the take near their ends "
               f"(up to {table.max():.0%} at the nearest frames)")
    return out


def _with_spline(motion, out, spline, e_out, rigid_alone, rigid_of, report, cfg):
    """``out`` with each gap blended with a cubic spline of its point through the take
    (:func:`~.baselines.fill_spline`) and its pattern fill (:func:`~.baselines.fill_pattern`, at
    ``pattern_weight``) by inverse errors per sample: the spline's and the pattern's on up
    to ``spline_copies`` copies of the gap itself (same point, same length, the nearest
    frames where it is observed), ``out``'s on the point's copies (``e_out``, per point; NaN
    where it has none, infinite where ``out`` left some of them open) or, where
    ``rigid_alone`` says the rigid estimate fills the point alone, that estimate's
    (``rigid_of(hidden)``: it on the samples ``hidden`` with those hidden) on the spline's
    copies; ``spline`` is that spline of the take. Over a few frames a point moves along a
    smooth curve that the spline follows within a millimetre, closer than any estimate carried from
    other points; over longer gaps its error grows fast, with a tail its copies do not foresee, so
    only gaps of up to ``spline_seconds`` take part. Gaps at the take's ends (no spline
    across them: :func:`_with_pattern_ends`) and points without copies keep ``out``;
    the pattern joins only where a partner spans the gap and each of its copies. Where more
    than ``body_gone`` of the points are gone over the gap, ``out``'s error is taken
    ``gone_doubt`` times over (its copies saw more of the body). Returns the
    blend and, per gap blended (``(point, first frame)``), the spline's and the pattern's shares
    and the blend's expected squared error (the errors as if independent)."""
    from .baselines import fill_pattern

    missing = motion.missing
    smooth = _smooth_of(motion, cfg)
    # copy k of every gap goes into round k: copies of one round never meet, those of one gap
    # never overlap, and all lie within spline_reach gap lengths of their gap
    rounds, copies = np.zeros((cfg.spline_copies,) + missing.shape, bool), []
    for p, a, b in gap_runs(missing):
        if (a == 0 or b == len(missing) - 1 or np.isnan(e_out[p])
                or b - a + 1 > _spline_frames(motion.fps, cfg)):
            continue
        length, own, starts = b - a + 1, missing[:, p].copy(), []
        for k, hidden in enumerate(rounds):
            start = _copy_start(own | hidden[:, p], a, length, cfg.spline_margin,
                                cfg.spline_reach * (length + cfg.spline_margin))
            if start is not None:
                hidden[start:start + length, p] = own[start:start + length] = True
                starts.append((k, start))
        if starts:
            copies.append((p, a, b, starts))
    if not copies:
        return out, {}
    short = np.zeros_like(missing)
    for p, a, b, _ in copies:
        short[a:b + 1, p] = True
    donors = {}  # the pattern's donor statistics of the take, for the gaps and the copies alike
    pattern = fill_pattern(motion.positions, only=short, cache=donors)

    def hide(hidden):
        return np.where(hidden[..., None], np.nan, motion.positions)

    error = _round_errors(rounds, motion.positions, lambda hidden: smooth(hide(hidden), hidden))
    pattern_error = _round_errors(rounds, motion.positions, lambda hidden: fill_pattern(
        hide(hidden), only=hidden, cache=donors))
    # where the rigid estimate alone fills a point, it is scored on the spline's own copies
    if rigid_alone[[p for p, _, _, _ in copies]].any():
        rigid_error = _round_errors(rounds, motion.positions, rigid_of)
    out, shares = out.copy(), {}
    for p, a, b, starts in copies:
        def on_copies(error):
            return np.mean([error[k][s:s + b - a + 1, p].mean() for k, s in starts])

        e_spline, e_here, e_pattern = on_copies(error), e_out[p], on_copies(pattern_error)
        if rigid_alone[p]:
            e_rigid = on_copies(rigid_error)
            e_here = e_rigid if np.isfinite(e_rigid) else e_here
        if not (np.isfinite(e_pattern) and np.isfinite(pattern[a:b + 1, p]).all()):
            e_pattern = np.inf  # no donor spans the gap or one of its copies
        e_here = _off_the_spline(out, spline, missing, p, a, b, e_here, e_spline, cfg)
        e_pattern = _off_the_spline(pattern, spline, missing, p, a, b, e_pattern, e_spline, cfg)
        if _body_gone(missing, a, b, cfg.body_gone):  # the fill's copies saw more of the body
            e_here *= cfg.gone_doubt
        w, squared = _weigh_in(out, p, a, b, (spline, pattern), (e_here, e_spline, e_pattern),
                               (1.0, 1.0, cfg.pattern_weight))
        shares[p, a] = w[1], w[2], squared
    eased = sum(spline_share >= 0.5 for spline_share, _, _ in shares.values())
    patterned = sum(pattern_share >= 0.25 for _, pattern_share, _ in shares.values())
    if eased or patterned:
        report(f"auto: of {len(copies)} short gaps a spline through the take carries {eased} "
               f"more than the other estimates, a partner's pattern a quarter or more of "
               f"{patterned}")
    return out, shares


def _smooth_of(motion, cfg):
    """The smooth track through the take's gaps that ``auto`` weighs, ``smooth(positions,
    only)`` of positions with NaN gaps: a cubic spline of each point
    (:func:`~.baselines.fill_spline`), ``learned`` of the way on to the take's own
    interpolator (:func:`~.baselines.fill_learned`) on the gaps that start in ``only`` and last
    at most ``learned_seconds``."""
    def smooth(positions, only):
        spline = baselines.fill_spline(positions)
        if not cfg.learned or not only.any():
            return spline
        learned = baselines.fill_learned(positions, spline, only,
                                         longest=cfg.learned_seconds * motion.fps)
        return spline + cfg.learned * (learned - spline)

    return smooth


def _learnt(missing, probe, fps, cfg):
    """Where ``auto``'s smooth track takes in the take's own interpolator (:func:`_smooth_of`),
    the gaps of ``missing`` and the copies ``probe`` ((frames, points) bool, at their first
    frames): every one of up to ``spline_seconds``, and a longer gap where more than
    ``body_gone`` of the points are gone (over half a second with few points gone its
    copies vouched for it more than the gaps bore out), with the longer copies of its point."""
    shortest = _spline_frames(fps, cfg)
    gaps, copies = np.zeros_like(missing), np.zeros_like(probe)
    gone = np.zeros(missing.shape[1], bool)
    for p, a, b in gap_runs(missing):
        gaps[a, p] = b - a + 1 <= shortest or _body_gone(missing, a, b, cfg.body_gone)
        gone[p] |= b - a + 1 > shortest and gaps[a, p]
    for p, a, b in gap_runs(probe):
        copies[a, p] = b - a + 1 <= shortest or gone[p]
    return gaps, copies


def _body_gone(missing, a, b, share):
    """Whether more than ``share`` of the points are gone on the mean over the frames ``a``-``b``
    (a subject half out of the volume, a prop in the way, a dropped frame)."""
    return bool(missing[a:b + 1].mean() > share)


def _off_the_spline(estimate, spline, missing, p, a, b, e_estimate, e_spline, cfg):
    """``estimate``'s expected squared error per sample on the gap ``a``-``b`` of point ``p``
    (``e_estimate``, from copies), raised where more than ``body_gone`` of the points
    are gone on the mean over the gap (``missing``: the take's) to at least the
    square of its RMS distance from ``spline`` less ``off_spline`` times the spline's
    own expected RMS error (``e_spline``: squared, per sample): by the triangle inequality it is
    off by about that much, whatever its copies said. With most of the body gone the partners
    left are far and the knowledge base's models see little, so copies taken where more was
    seen vouch for it less than for the spline, which needs nothing but the point's own track
    (on bursts of the tuning takes the fill strayed 4-9 times further than its copies
    foretold)."""
    if not (np.isfinite(e_estimate) and _body_gone(missing, a, b, cfg.body_gone)):
        return e_estimate
    squared = np.sum((estimate[a:b + 1, p] - spline[a:b + 1, p]) ** 2, axis=1)
    known = np.isfinite(squared)
    if not known.any():
        return e_estimate
    apart = np.sqrt(squared[known].mean())
    return max(e_estimate, max(apart - cfg.off_spline * np.sqrt(e_spline), 0.0) ** 2)


def _with_pattern_ends(motion, out, e_out, rigid_alone, rigid_of, report, cfg):
    """``out`` with each gap of up to ``spline_seconds`` at a clip end (no observation
    on one side: no spline across it) blended with its pattern fill from the one end
    (:func:`~.baselines.fill_pattern`, at ``pattern_weight``) and, on a marker set, the
    take's own interpolator from its one key (:func:`~.baselines.fill_learned_ends`, at
    ``learned_ends_weight``) by inverse errors per sample: theirs on up to
    ``spline_copies`` one-sided copies of the gap (the
    point hidden from the copy to the same clip end, so each copy has the one end its gap has,
    at the nearest frames where it is observed), ``out``'s on the point's copies (``e_out``) or,
    where ``rigid_alone`` says the rigid estimate fills the point alone, that estimate's
    (``rigid_of(hidden)``) on the same one-sided copies. Over a few frames a partner's trajectory
    with the offset at the one end carries a marker closely; the rigid estimate from one end
    turns with three donors' noise. Returns the blend and, per gap blended (``(point, first
    frame)``), the smooth track's share (the learned one's), the pattern's and the blend's
    expected squared error."""
    from .baselines import fill_learned_ends, fill_pattern

    missing = motion.missing
    frames = len(missing)
    shortest = _spline_frames(motion.fps, cfg)
    rounds = np.zeros((cfg.spline_copies,) + missing.shape, bool)  # hidden, per round
    copies, ends = [], np.zeros_like(missing)
    for p, a, b in gap_runs(missing):
        length = b - a + 1
        if (a == 0) == (b == frames - 1) or length > shortest or not np.isfinite(e_out[p]):
            continue
        ends[a:b + 1, p] = True
        seen, starts = ~missing[:, p], []
        shift = length + cfg.spline_margin
        reach = cfg.spline_reach * shift
        while len(starts) < cfg.spline_copies and shift <= reach and shift + length < frames:
            lo = shift if a == 0 else frames - shift - length
            key = lo + length if a == 0 else lo - 1
            k = len(starts)
            if seen[lo:lo + length].all() and seen[key] and not rounds[k, key, p]:
                rounds[k, :lo + length, p] |= a == 0
                rounds[k, lo:, p] |= a > 0
                starts.append((k, lo))
                shift += length + cfg.spline_margin
            else:
                shift += 1
        if starts:
            copies.append((p, a, b, starts))
    if not copies:
        return out, {}
    donors = {}  # the pattern's donor statistics of the take, for the gaps and the copies alike
    pattern = fill_pattern(motion.positions, only=ends, cache=donors)

    pattern_error = _round_errors(rounds, motion.positions, lambda hidden: fill_pattern(
        np.where(hidden[..., None], np.nan, motion.positions), only=hidden, cache=donors))
    learned = learned_error = None
    carried = np.zeros_like(ends)  # the gaps short enough for it, at their first frames
    for p, a, b, _ in copies:
        carried[a, p] = b - a + 1 <= cfg.learned_ends_seconds * motion.fps
    # (a skeleton's joints lost by it: docs/DESIGN.md)
    if motion.parents is None and carried.any():
        learned = fill_learned_ends(motion.positions, only=carried)
        learned_error = _round_errors(rounds, motion.positions, lambda hidden: fill_learned_ends(
            np.where(hidden[..., None], np.nan, motion.positions), only=hidden))
    rigid_error = (_round_errors(rounds, motion.positions, rigid_of)
                   if rigid_alone[[p for p, _, _, _ in copies]].any() else None)
    out, shares = out.copy(), {}
    for p, a, b, starts in copies:
        def on_copies(error):
            return np.mean([error[k][lo:lo + b - a + 1, p].mean() for k, lo in starts])

        e_here, e_pattern = e_out[p], on_copies(pattern_error)
        if rigid_alone[p]:
            e_rigid = on_copies(rigid_error)
            e_here = e_rigid if np.isfinite(e_rigid) else e_here
        if not (np.isfinite(e_pattern) and np.isfinite(pattern[a:b + 1, p]).all()):
            e_pattern = np.inf  # no donor spans the gap or one of its copies
        e_learned = np.inf if learned is None else on_copies(learned_error)
        if not (np.isfinite(e_learned) and np.isfinite(learned[a:b + 1, p]).all()):
            e_learned = np.inf  # none on a skeleton, too few frames behind the key, or windows
        if np.isinf(e_pattern) and np.isinf(e_learned):
            continue
        w, squared = _weigh_in(out, p, a, b, (learned, pattern), (e_here, e_learned, e_pattern),
                               (1.0, cfg.learned_ends_weight, cfg.pattern_weight))
        shares[p, a] = w[1], w[2], squared
    learnt = sum(learned_share >= 0.25 for learned_share, _, _ in shares.values())
    patterned = sum(pattern_share >= 0.25 for _, pattern_share, _ in shares.values())
    if learnt or patterned:
        report(f"auto: of {len(shares)} short gaps at the take's ends the take's own "
               f"interpolator from the one key carries a quarter or more of {learnt}, a "
               f"partner's pattern of {patterned}")
    return out, shares


def _with_all_gone_learnt(motion, out, report, cfg):
    """``out`` with each marker gap where nearly all of the body is gone at once
    (``all_gone``; longer than ``spline_seconds``, of up to
    ``learned_seconds``, both ends in the take) moved ``all_gone_share`` of the
    way on to the take's own interpolator (:func:`~.baselines.fill_learned`; a cubic spline where
    the take has too few windows), and the set of those gaps (``(point, first frame)``). A
    skeleton's joints keep their fill (not measured there)."""
    if motion.parents is not None or not cfg.all_gone_share:
        return out, set()
    missing = motion.missing
    gaps = {(p, a): b for p, a, b in _longer_gaps(missing, motion.fps, cfg)
            if b - a + 1 <= cfg.learned_seconds * motion.fps
            and _body_gone(missing, a, b, cfg.all_gone)}
    if not gaps:
        return out, set()
    only = np.zeros_like(missing)
    for p, a in gaps:
        only[a, p] = True
    learned = baselines.fill_learned(motion.positions, only=only)
    out = out.copy()
    for (p, a), b in gaps.items():
        out[a:b + 1, p] += cfg.all_gone_share * (learned[a:b + 1, p] - out[a:b + 1, p])
    report(f"auto: {len(gaps)} gaps where nearly all of the body is gone go "
           f"{cfg.all_gone_share:.0%} of the way on to the take's own interpolator")
    return out, set(gaps)


def _with_holes_splined(motion, out, report, cfg):
    """``out`` with the holes no estimate reached filled by a cubic spline through the point's
    values (seen and filled; :func:`_smooth_of`): runs of a point's missing frames where ``out``
    has no value, with a value on both sides. There no knowledge base models the point (none
    given, or it lacks the point) and fewer than three of its rigid partners are seen: frames
    where every marker is gone at once (a dropped camera frame, the subject out of the volume),
    whose neighbours show where each one was. Runs at a clip's end stay open (nothing on the far
    side). Returns the fill and the gaps the spline filled alone (``(point, first frame)``)."""
    missing = motion.missing
    hole = missing & np.isnan(out[..., 0])
    inside = np.zeros_like(hole)
    for p, a, b in gap_runs(hole):
        inside[a:b + 1, p] = a > 0 and b < len(hole) - 1
    if not inside.any():
        return out, []
    known = np.where(missing[..., None], out, motion.positions)
    out = np.where(inside[..., None], _smooth_of(motion, cfg)(known, inside), out)
    alone = [(p, a) for p, a, b in gap_runs(missing) if inside[a:b + 1, p].all()]
    runs = gap_runs(inside)
    report(f"auto: {len(runs)} hole{'s' if len(runs) > 1 else ''} no other estimate reached "
           f"(fewer than three partners seen, no knowledge base's model) take a spline through "
           f"the take: {int(inside.sum())} samples of {int(inside.any(axis=0).sum())} points, "
           f"the longest {max(b - a + 1 for _, a, b in runs)} frames")
    return out, alone


def _round_errors(rounds, truth, fill):
    """Per round of copies (``rounds``: (round, frames, points) bool, the samples hidden),
    ``fill(hidden)``'s squared error against ``truth`` (frames, points); None for a round that
    hides nothing."""
    return [np.sum((fill(hidden) - truth) ** 2, axis=2) if hidden.any() else None
            for hidden in rounds]


def _weigh_in(out, p, a, b, others, errors, weights):
    """``out``'s gap ``a..b`` of point ``p`` blended in place with the ``others`` (whole
    estimates of the take) by ``weights`` over ``errors`` (``out``'s first: inverse-error
    weights); returns the shares and the blend's expected squared error (the errors as if
    independent). An estimate of no share is left out (it may have no value there)."""
    errors = np.asarray(errors)
    w = np.asarray(weights) / (errors + 1e-24)
    w /= w.sum()
    blend = w[0] * out[a:b + 1, p] if w[0] else 0.0
    for share, other in zip(w[1:], others):
        if share:
            blend = blend + share * other[a:b + 1, p]
    out[a:b + 1, p] = blend
    return w, float(np.sum(w[w > 0] ** 2 * errors[w > 0]))


def _spline_frames(fps, cfg):
    """The longest gap (frames) that ``auto`` scores against a spline through the take:
    ``spline_seconds``."""
    return round(cfg.spline_seconds * fps)


def _carried_closely(missing, spread, within, fps, cfg):
    """The missing samples whose rigid donors keep within ``within`` (metres, RMS spread) of
    them, in gaps longer than ``spline_seconds`` (shorter ones are scored against a
    spline through the take, :func:`_with_spline`, on their own copies)."""
    shortest = _spline_frames(fps, cfg)
    longer = np.zeros_like(missing)
    for p, a, b in gap_runs(missing):
        longer[a:b + 1, p] = b - a + 1 > shortest
    with np.errstate(invalid="ignore"):
        return longer & (spread <= within)


def _joined(e_kb, e_other, ramp=None):
    """Another estimate joined to the knowledge base's by inverse errors on the copies (per
    point, squared errors ``e_kb`` and ``e_other``; inf: none): its share (0 where neither has a
    finite error) and the joined estimate's expected error. With ``ramp`` it joins only where
    it refilled the copies better, its share opening from 0 at equal errors to the full inverse
    error share where that share is ``ramp`` above one half (``join_ramp``)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.nan_to_num((1.0 / e_other) / (1.0 / e_kb + 1.0 / e_other))
        if ramp is not None:
            share = share * np.clip((share - 0.5) / ramp, 0.0, 1.0)
        # the two estimates' errors taken as independent (at the full share: 1 / (1/a + 1/b))
        error = (np.where(share < 1, (1 - share) ** 2 * e_kb, 0.0)
                 + np.where(share > 0, share ** 2 * e_other, 0.0))
    return share, error


def _offset_variance(missing, donors):
    """Per point, the least variance of its offset to a partner seen through all of its gaps,
    from the pattern's donor statistics (``donors``, :func:`~.baselines.fill_pattern`'s cache);
    0 for points it has none of."""
    out = np.zeros(missing.shape[1])
    for p, variance in donors.items():
        usable = ~missing[missing[:, p]].any(axis=0)
        least = np.min(np.where(usable, variance, np.inf))
        out[p] = least if np.isfinite(least) else 0.0
    return out


def _spread_floor(missing, probe, spread, cfg):
    """Per point, the least squared error (summed over its copies) of the rigid estimate where
    its copies are shorter than its gaps (``spread_cap``); 0 elsewhere."""
    with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # points with no spread: nan
        longer = np.clip(_mean_run(missing) / _mean_run(probe) - 1, 0, 1)
        mean = np.nanmean(np.where(missing, spread ** 2, np.nan), axis=0)
    return np.nan_to_num(cfg.spread_cap * longer * mean * probe.sum(axis=0))


def _mean_run(mask):
    """Mean length of each column's runs of True (nan where none)."""
    runs = np.bincount([p for p, _, _ in gap_runs(mask)], minlength=mask.shape[1])
    with np.errstate(invalid="ignore", divide="ignore"):
        return mask.sum(axis=0) / runs


def validation_gaps(missing, per_point=3, margin=10, least=0, enough=0):
    """Copies of the gaps where their points are observed: for each gap of each point, the
    nearest shift (by at least the gap's length plus ``margin``) that lands on observed frames
    with an observed frame on either side, ``per_point`` per point, more where those hold fewer
    than ``least`` frames; a point whose copies hold fewer than ``enough`` frames (or ``least``)
    when its gaps run out has them copied again, each at the nearest shift left, as long as
    there is room. A gap of several points at the same frames lands at the same shift for all of
    them when it can. Where a take has no room for a full-length copy of a point's gaps, half
    (then a quarter) of the length is tried, down to 4 frames."""
    probe = np.zeros_like(missing)
    runs = sorted(gap_runs(missing), key=lambda r: (r[1], r[2], r[0]))
    count = np.zeros(missing.shape[1], dtype=int)
    copied = np.zeros(missing.shape[1], dtype=int)  # frames
    for shrink in (1, 2, 4):
        again, added = False, True
        while added:  # each pass copies the gaps of the points that need more once more
            added = False
            for p, a, b in runs:
                length = (b - a + 1) // shrink
                if ((count[p] >= per_point and copied[p] >= least)
                        or (again and copied[p] >= max(least, enough))
                        or (shrink > 1 and count[p]) or length < min(4, b - a + 1)):
                    continue
                start = _copy_start(missing[:, p] | probe[:, p], a, length, margin)
                if start is not None:
                    probe[start:start + length, p] = True
                    count[p] += 1
                    copied[p] += length
                    added = True
            again = True
    return probe


def _copy_start(busy, a, length, margin, reach=None):
    """Where a copy of a gap (starting at ``a``, ``length`` frames) of a point that is ``busy``
    (missing, or copied already) at some frames goes: the nearest start at least ``length +
    margin`` frames away (at most ``reach``) whose frames, and one either side, are not busy;
    None where there is none."""
    taken = np.concatenate([[0], np.cumsum(busy)])
    starts = np.arange(1, len(busy) - length)
    distance = np.abs(starts - a)
    ok = (taken[starts + length + 1] - taken[starts - 1] == 0) & (distance >= length + margin)
    if reach is not None:
        ok &= distance <= reach
    if not ok.any():
        return None
    return int(starts[ok][np.argmin(distance[ok])])
