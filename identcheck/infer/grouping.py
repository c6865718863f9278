"""Markers into rigid segments, from the trial alone.

Two markers on one rigid segment keep their distance; two markers across a joint do not, unless the joint
hardly moves. So every pair's distance is followed over the frames in which both are seen, and its *spread*
is half the range of its central 95 % (:data:`SPREAD_PERCENTILES`): robust to a few frames of gross error or a
short label swap, and in millimetres, so that it reads against the noise and the soft-tissue wobble.

The tolerance below which a pair counts as rigid comes from the data (:func:`rigidity_tolerance`):

- the measurement noise of a distance, σ_d, from the frame-to-frame scatter of each marker's most rigid pair
  (:func:`identcheck.estimate.noise.frame_to_frame_sd`: second differences, which slow motion hardly reaches);
  a rigid pair's spread under Gaussian noise alone is 1.96 σ_d, and :data:`NOISE_FACTOR` σ_d is twice that;
- the wobble: every marker's smallest spread to any other marker (its nearest rigid partner's, for a marker
  that has one), their median w. Soft tissue moves skin markers by a few mm on their segment, and the spreads
  inside a segment are then a few times w: :data:`NEAREST_FACTOR` w, but at most :data:`MAX_WOBBLE_MM` above
  the noise part (a trial of one-marker segments has no rigid pairs, and w is then a joint's spread);
- at least :data:`FLOOR_MM` (noise-free data).

Computed points exported beside the markers (virtual joint centres) are rigid with their segment to round-off;
markers whose nearest spread is below :data:`COMPUTED_MM` are left out of these estimates.

The segments are then found as rigid bodies (:func:`partition`): triples of pairwise rigid markers are posed
in every frame, and the markers that stay still in a triple's frame (within the same tolerance: a marker's
95th-percentile deviation from its body-fixed position, which for isotropic scatter matches a pair's spread)
join it, largest body first. Markers left over pair up by their distances; a marker rigid with no other is left
alone (``loose``): the tree step tries to attach it as a one-marker segment, and otherwise reports it
unassigned. Last, markers left loose or paired join groups held apart from everything else
(:mod:`identcheck.infer.separated_groups`): skin markers on the moving segment of a functional trial wobble more
than the one tolerance, which the still rest of the body sets.

A static trial (no pair's spread reaches :data:`STATIC_MM` and :data:`STATIC_SHARE` of the markers' size) is
refused rather than grouped by noise.
"""
from __future__ import annotations

import difflib
import re
import warnings
from dataclasses import dataclass, field

import numpy as np

from identcheck.errors import InputError
from identcheck.estimate.noise import MIN_SAMPLES_PER_PAIR, frame_to_frame_sd
from identcheck.geometry.poses import MIN_MARKERS
from identcheck.infer.body_frames import body_deviation, evenly_spaced, is_rigid
from identcheck.infer.separated_groups import widen

SPREAD_PERCENTILES = (2.5, 97.5)
"""A pair's spread: half the distance between these percentiles of its distance over the frames."""
NOISE_FACTOR = 4.0
"""Rigid pairs' spreads under noise alone are 1.96 σ_d; the tolerance is at least this many σ_d."""
NEAREST_FACTOR = 3.0
"""The tolerance is at least this many times the median nearest-partner spread (the wobble w)."""
MAX_WOBBLE_MM = 6.0
"""... but the wobble part adds at most this much to the noise part (mm)."""
FLOOR_MM = 0.5
COMPUTED_MM = 0.05
"""A marker whose nearest partner's spread is below this (mm) is a computed point (a virtual joint centre, a
duplicate): left out of the noise and wobble estimates, which are about measured markers."""
"""Smallest tolerance (mm): noise-free data would otherwise split on round-off."""
COMPETE_ROUNDS = 6
"""Most rounds of competition between the bodies for the markers (:func:`_compete`)."""
REASSIGN_MARGIN = 1.5
"""A marker leaves its body only for one in which it deviates this many times less."""
MAX_GROUPING_MARKERS = 500
"""The most markers grouped into segments: the grouping compares every pair and merges groups one at a time, a time
that grows faster than the square of the markers (random trials of 12 frames: 100 markers 4 s, 400 markers 44 s;
3000 had not ended after 180 s). A full body with hands and a face is well below; more is refused up front, with
``--segments`` as the way on, so that the command ends in bounded time."""
MAX_GROUPING_FRAMES = 600
"""The rigid bodies are found on at most this many frames, evenly spread (the spreads use every frame)."""
STATIC_MM = 15.0
"""A trial in which no marker pair's spread reaches this (mm) is static and refused (biobuddy's anatomical pose:
5.3 mm). Kept well below what joints that move at all leave: the smallest largest spread in 240 trials of the two
independent generators was 25.8 mm; standing still, sway and arm motion reach 29 mm (OpenSim's subject01_static,
which is therefore grouped, with every joint reported as hardly rotating)."""
STATIC_SHARE = 0.03
"""... and below this share of the markers' median pairwise distance: a hand's or a finger's segments, 20-60 mm
across, leave spreads of a few mm when their joints move."""
PAIR_CHUNK = 4_000_000
"""Distances computed at once (frames x pairs), to bound memory on long trials with many markers."""


@dataclass(frozen=True)
class PairStatistics:
    """Every marker pair's distance statistics.

    Attributes
    ----------
    spread_mm : numpy.ndarray
        Shape (n_markers, n_markers): half the range between :data:`SPREAD_PERCENTILES` of the pair's
        distance, mm; NaN where the pair is seen together in fewer than
        :data:`~identcheck.estimate.noise.MIN_SAMPLES_PER_PAIR` frames; 0 on the diagonal.
    common_frames : numpy.ndarray
        Shape (n_markers, n_markers), int: frames in which both are seen.
    xyz : numpy.ndarray
        The marker positions the statistics come from, shape (n_frames, n_markers, 3), mm (see :meth:`distance`).
    """

    spread_mm: np.ndarray
    common_frames: np.ndarray
    xyz: np.ndarray = field(repr=False)

    def distance(self, i: int, j: int) -> np.ndarray:
        """Distance between markers i and j in every frame, shape (n_frames,), mm, NaN where either is unseen."""
        return np.linalg.norm(self.xyz[:, i] - self.xyz[:, j], axis=1)


def _column_percentile(D: np.ndarray, n: np.ndarray, q: float) -> np.ndarray:
    """The q-th percentile of each column of D over its finite values (n of them), linear interpolation as
    :func:`numpy.nanpercentile`, for all columns at once (NaN sorts last)."""
    srt = np.sort(D, axis=0)
    pos = np.clip(q / 100.0 * (np.maximum(n, 1) - 1), 0, None)
    lo = np.floor(pos).astype(int)
    hi = np.minimum(lo + 1, np.maximum(n - 1, 0))
    cols = np.arange(D.shape[1])
    return srt[lo, cols] + (pos - lo) * (srt[hi, cols] - srt[lo, cols])


def pair_statistics(xyz) -> PairStatistics:
    """Spread and common frames of every marker pair.

    Parameters
    ----------
    xyz : array, shape (n_frames, n_markers, 3)
        Marker positions, mm, NaN where occluded.

    Returns
    -------
    PairStatistics
    """
    xyz = np.asarray(xyz, dtype=float)
    F, M, _ = xyz.shape
    spread = np.full((M, M), np.nan)
    common = np.zeros((M, M), dtype=int)
    np.fill_diagonal(spread, 0.0)
    ii, jj = np.triu_indices(M, 1)
    step = max(1, PAIR_CHUNK // max(F, 1))
    for k in range(0, len(ii), step):
        i, j = ii[k:k + step], jj[k:k + step]
        D = np.linalg.norm(xyz[:, i] - xyz[:, j], axis=2)               # (F, pairs)
        n = np.isfinite(D).sum(axis=0)
        lo, hi = (_column_percentile(D, n, q) for q in SPREAD_PERCENTILES)
        s = np.where(n >= MIN_SAMPLES_PER_PAIR, (hi - lo) / 2.0, np.nan)
        spread[i, j] = spread[j, i] = s
        common[i, j] = common[j, i] = n
    np.fill_diagonal(common, np.isfinite(xyz).all(axis=2).sum(axis=0))
    return PairStatistics(spread, common, xyz)


# ---------------------------------------------------------------------- the tolerance
@dataclass(frozen=True)
class Tolerance:
    """The spread below which a pair counts as rigid, and what it was made of (all mm).

    Attributes
    ----------
    tolerance_mm : float
    distance_noise_mm : float
        σ_d, the noise of a distance from frame to frame (NaN when no pair had enough consecutive frames).
    wobble_mm : float
        w, the median over markers of the smallest spread to any other marker.
    rule : str
        Which term set the tolerance, in words.
    """

    tolerance_mm: float
    distance_noise_mm: float
    wobble_mm: float
    rule: str

    def to_dict(self) -> dict:
        return {"tolerance_mm": _num(self.tolerance_mm), "distance_noise_mm": _num(self.distance_noise_mm),
                "wobble_mm": _num(self.wobble_mm), "rule": self.rule}


def rigidity_tolerance(stats: PairStatistics) -> Tolerance:
    """The rigid-pair tolerance from the data (module docstring).

    Parameters
    ----------
    stats : PairStatistics

    Returns
    -------
    Tolerance
    """
    S = stats.spread_mm.copy()
    np.fill_diagonal(S, np.nan)
    has = np.isfinite(S).any(axis=1)
    if not has.any():
        return Tolerance(FLOOR_MM, float("nan"), float("nan"), f"no pair seen together in "
                         f"{MIN_SAMPLES_PER_PAIR}+ frames: the floor, {FLOOR_MM:g} mm")
    rows = np.flatnonzero(has)
    nearest = np.nanargmin(S[rows], axis=1)
    measured = S[rows, nearest] >= COMPUTED_MM                # computed points (a joint centre exported beside
    if measured.any():                                        # its markers) are rigid beyond any measurement
        rows, nearest = rows[measured], nearest[measured]
    w = float(np.median(S[rows, nearest]))
    noise = [frame_to_frame_sd(stats.distance(i, j))[0] for i, j in zip(rows, nearest)]
    noise = np.array([x for x in noise if np.isfinite(x)])
    sigma_d = float(np.median(noise)) if len(noise) else float("nan")
    t_noise = NOISE_FACTOR * sigma_d if np.isfinite(sigma_d) else 0.0
    t_wobble = min(NEAREST_FACTOR * w, t_noise + MAX_WOBBLE_MM)
    tol = max(FLOOR_MM, t_noise, t_wobble)
    if tol == FLOOR_MM:
        rule = f"the floor, {FLOOR_MM:g} mm (the data are nearly noise-free)"
    elif tol == t_noise:
        rule = f"{NOISE_FACTOR:g} x the distance noise {sigma_d:.3g} mm"
    elif t_wobble == NEAREST_FACTOR * w:
        rule = f"{NEAREST_FACTOR:g} x the median nearest-partner spread {w:.3g} mm (soft-tissue wobble and noise)"
    else:
        rule = (f"the noise part {t_noise:.3g} mm plus at most {MAX_WOBBLE_MM:g} mm of wobble (the median "
                f"nearest-partner spread, {w:.3g} mm, is large: few markers share a segment)")
    return Tolerance(float(tol), sigma_d, w, rule)


# ---------------------------------------------------------------------- rigid bodies
def _agglomerate(xyz: np.ndarray, S: np.ndarray, tolerance: float, nodes: list) -> list:
    """Complete linkage on the pair spreads `S` (inf: not rigid) over `nodes`, with the pose test on every merge
    of four or more markers (:func:`partition`); then a marker left in a group of one or two joins a larger group
    with which it passes both tests."""
    n = len(nodes)
    groups = [[nodes[k]] for k in range(n)]
    D = S[np.ix_(nodes, nodes)].copy()                   # group-to-group largest spread
    np.fill_diagonal(D, np.inf)
    alive = np.ones(n, dtype=bool)
    while n:
        masked = np.where(alive[:, None] & alive[None, :], D, np.inf)
        a, b = divmod(int(np.argmin(masked)), n)
        if not masked[a, b] <= tolerance:
            break
        a, b = min(a, b), max(a, b)
        if not is_rigid(xyz, sorted(groups[a] + groups[b]), tolerance):
            D[a, b] = D[b, a] = np.inf                  # never these two
            continue
        groups[a] += groups[b]
        groups[b] = []
        alive[b] = False
        D[a] = D[:, a] = np.maximum(D[a], D[b])
        D[a, a] = np.inf
    groups = [sorted(g) for g in groups if g]
    moved = True
    while moved:                                        # orphans of a cross-joint pair go home
        moved = False
        for g in sorted(groups, key=len):
            if len(g) > 2:
                continue
            for i in list(g):
                homes = sorted((float(S[i, h].max()), h[0], k) for k, h in enumerate(groups)
                               if h is not g and len(h) >= len(g) and S[i, h].max() <= tolerance)
                for _, _, k in homes:
                    if is_rigid(xyz, sorted(groups[k] + [i]), tolerance):
                        groups[k] = sorted(groups[k] + [i])
                        g.remove(i)
                        moved = True
                        break
            groups = [h for h in groups if h]
            if moved:
                break
    return groups


def _compete(xyz: np.ndarray, S: np.ndarray, tolerance: float, groups: list) -> list:
    """One round of competition between the bodies (groups of three or more): every marker goes to the body in
    whose frame it stays stillest (:func:`body_deviation`, scaled by the amplification; a member of a body of four or
    more is seen in the frame of the others, of a body of three in the body's own), staying in its own body unless
    another is :data:`REASSIGN_MARGIN` times stiller, and to none when no body holds it within `tolerance`. Bodies
    left with fewer than three markers dissolve, and the markers without a body are grouped again
    (:func:`_agglomerate`)."""
    bodies = [g for g in groups if len(g) >= MIN_MARKERS]
    if not bodies:
        return groups
    cols = sorted(m for g in groups for m in g)
    where = {m: k for k, g in enumerate(bodies) for m in g}
    C = np.full((len(cols), len(bodies)), np.inf)
    row = {m: i for i, m in enumerate(cols)}
    for k, body in enumerate(bodies):
        d, a = body_deviation(xyz, body, cols)
        C[:, k] = d / a
        for m in body:
            if len(body) > MIN_MARKERS:
                d1, a1 = body_deviation(xyz, [o for o in body if o != m], [m])
                C[row[m], k] = float(d1[0] / a1[0])
            else:
                C[row[m], k] = float(d[row[m]])          # in the fit: no amplification
    new = [[] for _ in bodies]
    left = []
    for m in cols:
        c = C[row[m]]
        k = int(np.argmin(c))
        own = where.get(m)
        if own is not None and c[own] <= tolerance and c[own] <= REASSIGN_MARGIN * c[k]:
            new[own].append(m)
        elif c[k] <= tolerance:
            new[k].append(m)
        else:
            left.append(m)
    kept = []
    for g in new:
        (kept.append(sorted(g)) if len(g) >= MIN_MARKERS else left.extend(g))
    return kept + _agglomerate(xyz, S, tolerance, sorted(left))


def partition(xyz, spread: np.ndarray, tolerance: float, usable=None) -> tuple[list, list, list]:
    """Groups of markers that move as rigid bodies; and the markers rigid with none.

    First complete-linkage agglomeration on the pair spreads: the two groups whose *largest* pair spread is the
    smallest are merged while it is within `tolerance` (ties: the earlier markers first), unless the merged group
    of four or more markers fails the pose test (:func:`~identcheck.infer.body_frames.is_rigid`): a distance sees a
    marker move in one direction, a pose in all three. A marker left in a group of one or two then joins a larger
    group with which it passes both tests. Then the bodies compete for the markers (:func:`_compete`) until the
    grouping stops changing (at most :data:`COMPETE_ROUNDS` rounds): with soft tissue, the tolerance can let a marker
    near a joint pass for rigid with both segments, and it belongs to the one in whose frame it stays stillest. Last,
    markers left loose or paired by the one tolerance join groups that stay well apart from everything else
    (:func:`identcheck.infer.separated_groups.widen`): skin markers on the moving segment of a functional trial
    wobble more than the still rest of the body, which sets the tolerance.

    Parameters
    ----------
    xyz : array, shape (n_frames, n_markers, 3)
        Marker positions, mm, NaN where occluded (at most :data:`MAX_GROUPING_FRAMES` frames, evenly spread, are
        used for the poses).
    spread : array, shape (n_markers, n_markers)
        Pair spreads, mm (NaN: not seen together often enough, counted as not rigid).
    tolerance : float
        Spread (and body-fixed deviation) at or below which markers are rigid, mm.
    usable : sequence of int, optional
        The markers to group (default all).

    Returns
    -------
    groups : list of list of int
        Each group's marker columns (2 or more), ascending; groups in order of their first column.
    loose : list of int
        Markers rigid with no other (ascending).
    widened : list of identcheck.infer.separated_groups.Widened
        The groups that gathered markers beyond the tolerance because they stay apart from everything else
        (:func:`identcheck.infer.separated_groups.widen`).
    """
    xyz = np.asarray(xyz, dtype=float)
    xyz = evenly_spaced(xyz, MAX_GROUPING_FRAMES)
    nodes = list(range(len(spread))) if usable is None else sorted(int(u) for u in usable)
    S = np.nan_to_num(np.asarray(spread, dtype=float), nan=np.inf)
    groups = _agglomerate(xyz, S, tolerance, nodes)
    seen = {_key(groups)}
    for _ in range(COMPETE_ROUNDS):
        groups = _compete(xyz, S, tolerance, groups)
        if _key(groups) in seen:
            break
        seen.add(_key(groups))
    out = sorted((sorted(g) for g in groups if len(g) >= 2), key=lambda g: g[0])
    loose = sorted(g[0] for g in groups if len(g) == 1)
    out, loose, widened = widen(xyz, S, tolerance, out, loose, nodes)
    return out, loose, widened


def _key(groups: list) -> frozenset:
    return frozenset(frozenset(g) for g in groups)


# ---------------------------------------------------------------------- the grouping
@dataclass(frozen=True)
class Grouping:
    """Markers in rigid groups.

    Attributes
    ----------
    groups : dict of str to tuple of str
        Group name → its marker labels (trial order). Inferred groups have 2+ markers and are named ``seg1``,
        ``seg2``, ... in the order of their first marker in the trial; given groups keep their names.
    loose : tuple of str
        Inferred only: markers rigid with no other marker (candidates for a one-marker segment).
    unused : dict of str to str
        Markers left out of the grouping → why (too few frames; not in the segments file).
    tolerance : Tolerance
    internal_spread_mm : dict of str to float
        Group → the largest spread between two of its markers (NaN for a one-marker group).
    source : str
        "inferred", or the segments file.
    warnings : tuple of str
    widened : dict of str to dict
        Inferred only: group → ``{"spread_mm", "separation_mm", "added", "note"}`` for each group that gathered
        markers beyond the tolerance (:func:`identcheck.infer.separated_groups.widen`): its largest internal
        spread, its smallest complete-linkage spread to the rest, the markers added, and the two readings in words;
        ``"bodies_merged"`` too (each body's markers) when the group joins rigid bodies whose joints hardly move in
        the trial (:func:`identcheck.infer.separated_groups.widen`). Such a group is an interpretation the data
        leave open, so the skeleton is not called settled.
    """

    groups: dict
    loose: tuple
    unused: dict
    tolerance: Tolerance
    internal_spread_mm: dict
    source: str
    warnings: tuple = ()
    widened: dict = field(default_factory=dict)
    spread_mm: np.ndarray = field(default=None, repr=False, compare=False)
    """Every pair's spread (:class:`PairStatistics`), marker columns in trial order."""

    def to_dict(self) -> dict:
        """The JSON's ``grouping``; ``too_rarely_seen``: the labelled markers an inferred grouping could not judge, seen
        in too few frames (markers a segments file leaves out are the user's choice, and unlabelled fragments,
        :func:`unlabelled`, no marker of the body: neither is listed)."""
        rare = sorted(m for m in self.unused if not unlabelled(m)) if self.source == "inferred" else []
        return {"source": self.source, **self.tolerance.to_dict(),
                "internal_spread_mm": {k: _num(v) for k, v in self.internal_spread_mm.items()},
                "widened": self.widened, "too_rarely_seen": rare}


UNLABELLED = re.compile(r"^(\*\d+|unlabell?ed\b.*)$", re.IGNORECASE)
"""Labels capture software gives trajectories no one labelled: Vicon Nexus ``*12``, Qualisys and Motive
``Unlabeled 1234`` (``Unlabelled`` too)."""


def unlabelled(label: str) -> bool:
    """Whether `label` names an unlabelled fragment (:data:`UNLABELLED`): a stray reflection or a piece of a marker's
    path the software did not join, which a short trial of a labelled capture often holds."""
    return bool(UNLABELLED.match(str(label).strip()))


def _num(x):
    return None if x is None or not np.isfinite(x) else float(x)


def _seen(xyz: np.ndarray) -> np.ndarray:
    return np.isfinite(xyz).all(axis=2).sum(axis=0)


def _never_visible(trial, labels) -> None:
    seen = _seen(trial.xyz)
    never = [m for m in labels if seen[trial.index(m)] == 0]
    if never:
        raise InputError([f"marker {m!r} is never visible in the trial (every sample is empty): fix its labelling, "
                          "or leave it out with --segments" for m in never], source=trial.source)


def _internal(stats: PairStatistics, cols) -> float:
    vals = [stats.spread_mm[a, b] for k, a in enumerate(cols) for b in cols[k + 1:]]
    vals = [v for v in vals if np.isfinite(v)]
    return float(max(vals)) if vals else float("nan")


def _refuse_static(stats: PairStatistics, labels, source: str, usable=None) -> None:
    """A static trial (:data:`STATIC_MM`, :data:`STATIC_SHARE`) is refused: its pairs' spreads are noise, sway and
    skin, and any grouping or tree drawn from them would be noise. Not judged when some pair of the `usable` markers
    is never seen together often enough (a spread unknown is not a spread small)."""
    cols = list(range(len(labels))) if usable is None else list(usable)
    if len(cols) < 2:
        return
    S = stats.spread_mm[np.ix_(cols, cols)].copy()
    np.fill_diagonal(S, 0.0)
    if not np.isfinite(S).all():
        return
    i, j = np.triu_indices(len(cols), 1)
    if not len(i):
        return
    k = int(np.argmax(S[i, j]))                          # a pair of two markers, even when every spread is 0
    a, b = int(i[k]), int(j[k])
    largest = float(S[a, b])
    few = evenly_spaced(stats.xyz, 50)[:, cols]
    with warnings.catch_warnings():                      # the markers' size: 50 frames are plenty
        warnings.simplefilter("ignore", RuntimeWarning)
        size = float(np.nanmedian(np.linalg.norm(few[:, i] - few[:, j], axis=2)))
    if largest < STATIC_MM and largest < STATIC_SHARE * size:
        raise InputError([f"the trial is static: no two markers change their distance by more than "
                          f"{largest:.3g} mm (spread, {labels[cols[a]]}-{labels[cols[b]]}), below {STATIC_MM:g} mm "
                          f"and {100 * STATIC_SHARE:g} % of the markers' median distance ({size:.3g} mm), which any "
                          "joint's motion leaves: the markers move as one rigid body up to noise and skin motion, "
                          "and no segments or joints can be inferred; record a trial in which each joint moves"],
                         source=source)


def group_markers(trial) -> Grouping:
    """Infer the rigid segments of a trial (module docstring).

    Parameters
    ----------
    trial : identcheck.trial.Trial

    Returns
    -------
    Grouping

    Raises
    ------
    InputError
        Fewer than two markers, a marker never visible, a static trial (:func:`_refuse_static`), or every marker
        rigid with every other (one rigid body: no joint to infer).
    """
    labels = trial.labels
    if len(labels) < 2:
        raise InputError([f"the trial has {len(labels)} marker(s); a skeleton needs at least two segments, each "
                          "with markers"], source=trial.source)
    _never_visible(trial, labels)
    seen = _seen(trial.xyz)
    unused = {m: f"seen in only {int(seen[i])} frame(s); grouping needs {MIN_SAMPLES_PER_PAIR}"
              for i, m in enumerate(labels) if seen[i] < MIN_SAMPLES_PER_PAIR}
    usable = [i for i, m in enumerate(labels) if m not in unused]
    if len(usable) < 2:
        raise InputError([f"the trial has {trial.n_frames} frame(s) ({len(labels) - len(usable)} of its {len(labels)} "
                          f"markers seen in fewer than {MIN_SAMPLES_PER_PAIR}): grouping markers into rigid segments "
                          f"reads how their distances change over a movement, and needs each marker seen in "
                          f"{MIN_SAMPLES_PER_PAIR} frames or more; record (or choose with --frames) a longer span"],
                         source=trial.source)
    if len(usable) > MAX_GROUPING_MARKERS:
        raise InputError([f"the trial has {len(usable)} markers to group, more than the {MAX_GROUPING_MARKERS} whose "
                          "grouping into rigid segments ends in reasonable time (it compares every pair of markers): "
                          "give the segments with --segments FILE, or a trial of the markers of the bodies to infer"],
                         source=trial.source)
    stats = pair_statistics(trial.xyz)
    _refuse_static(stats, labels, trial.source, usable)
    tol = rigidity_tolerance(stats)
    cols, loose, widened = partition(trial.xyz, stats.spread_mm, tol.tolerance_mm, usable)
    if len(cols) == 1 and len(cols[0]) == len(labels):
        raise InputError([f"all {len(labels)} markers move as one rigid body (every pair's distance stays within "
                          f"{tol.tolerance_mm:.3g} mm): there is no joint to infer; record a trial in which the "
                          "segments move relative to each other"], source=trial.source)
    groups = {f"seg{k}": tuple(labels[i] for i in g) for k, g in enumerate(cols, start=1)}
    internal = {f"seg{k}": _internal(stats, g) for k, g in enumerate(cols, start=1)}
    home = {i: f"seg{k}" for k, g in enumerate(cols, start=1) for i in g}
    wide = {}
    for w in widened:                                   # a body may grow twice: the entries add up
        entry = wide.setdefault(home[w.added[0]], {"spread_mm": 0.0, "separation_mm": float("inf"), "added": []})
        if w.bodies:
            entry["bodies_merged"] = [[labels[i] for i in b] for b in w.bodies]
        entry["spread_mm"] = max(entry["spread_mm"], w.spread_mm)
        entry["separation_mm"] = min(entry["separation_mm"], w.separation_mm)
        entry["added"] = sorted(entry["added"] + [labels[i] for i in w.added], key=labels.index)
    for name, entry in wide.items():
        new = len(entry["added"]) == len(groups[name])
        if entry.get("bodies_merged"):
            bodies = "; ".join(", ".join(b) for b in entry["bodies_merged"])
            entry["note"] = (f"{name} joins {len(entry['bodies_merged'])} rigid bodies ({bodies}) and "
                             f"{', '.join(entry['added'])}, which move with them: its markers move up to "
                             f"{entry['spread_mm']:.3g} mm relative to each other, more than the rigidity tolerance "
                             f"{tol.tolerance_mm:.3g} mm, but everything else moves at least "
                             f"{entry['separation_mm']:.3g} mm relative to them. The joints between those bodies "
                             "hardly move in this trial, and which of them carries the added markers (skin markers "
                             "wobbling) is a choice the trial cannot make; record those joints moving to tell the "
                             "segments apart")
            continue
        entry["note"] = (f"{', '.join(entry['added'])} " + ("form" if new else "joined") + f" {name} although its "
                         f"markers move up to {entry['spread_mm']:.3g} mm relative to each other, more than the "
                         f"rigidity tolerance {tol.tolerance_mm:.3g} mm, because everything else moves at least "
                         f"{entry['separation_mm']:.3g} mm relative to them: skin markers wobbling on one segment, or "
                         "segments joined by a joint that hardly moves in this trial")
    return Grouping(groups, tuple(labels[i] for i in loose), unused, tol, internal, "inferred", widened=wide,
                    spread_mm=stats.spread_mm)


def given_grouping(trial, segments: dict, source: str = "--segments") -> Grouping:
    """The user's grouping, checked against the trial; the tolerance is still measured, and a given segment
    whose markers move relative to each other by more than it is named in ``warnings``.

    Parameters
    ----------
    trial : identcheck.trial.Trial
    segments : dict of str to sequence of str
        Segment name → its markers (as :func:`identcheck.io.segments.read_segments` returns).
    source : str
        The segments file, named in messages.

    Raises
    ------
    InputError
        A marker the trial does not have (with the closest label), or one never visible in it; fewer than two
        segments; a static trial (:func:`_refuse_static`).
    """
    problems = []
    for name, markers in segments.items():
        for m in markers:
            if m not in trial.labels:
                close = difflib.get_close_matches(m, trial.labels, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                problems.append(f"segments.{name}: marker {m!r} is not in the trial {trial.source}{hint}")
    if len(segments) < 2:
        problems.append(f"{len(segments)} segment(s); a skeleton needs at least two")
    if problems:
        raise InputError(problems, source=source)
    listed = [m for ms in segments.values() for m in ms]
    try:
        _never_visible(trial, listed)
    except InputError as exc:
        raise exc.naming(source, f"(trial {trial.source}) ") from None
    stats = pair_statistics(trial.xyz)
    _refuse_static(stats, trial.labels, trial.source, [trial.index(m) for m in listed])
    tol = rigidity_tolerance(stats)
    groups = {name: tuple(markers) for name, markers in segments.items()}
    internal = {name: _internal(stats, [trial.index(m) for m in ms]) for name, ms in groups.items()}
    notes = tuple(f"segment {name!r}: its markers move by up to {v:.3g} mm relative to each other (spread), more "
                  f"than the rigidity tolerance {tol.tolerance_mm:.3g} mm: not one rigid body in this trial?"
                  for name, v in internal.items() if np.isfinite(v) and v > tol.tolerance_mm)
    unused = {m: f"not in {source}" for m in trial.labels if m not in set(listed)}
    return Grouping(groups, (), unused, tol, internal, source, notes, spread_mm=stats.spread_mm)
