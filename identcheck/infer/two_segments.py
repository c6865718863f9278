"""Groups that may be two segments: markers that move relative to the rest of their group more than noise allows.

Markers group together when their distances stay within a tolerance that allows for noise and skin wobble, so two
segments joined by a joint that hardly moves in the trial (or whose markers lie near a hinge's axis) can come out
as one group. Measured on held-out random skeletons, such merges were most of the wrong trees the tool called
settled.

With the marker noise σ known, a rigid group can be checked against it: seen in the pose of some of its markers
(part A, three or more), each other marker (part B) scatters about its body-fixed place by σ²(1 + f²) per
coordinate, f being how much A's own pose noise adds there (:func:`identcheck.geometry.poses.pose_noise_factor`).
The *motion ratio* of a split is the root of the mean, over B's markers and the frames, of the squared distance from
that place over 3σ²(1 + f²): about 1 for a rigid group whatever the split (0.85-1.15 for 95 % of 172 rigid groups of
five or more markers in two development draws of the independent skeleton generator), larger when B turns
relative to A. The splits tried are those of the group's own complete-linkage tree of pair spreads (each node
against the rest, either side posed). A group whose largest ratio is at least :data:`RATIO_LIMIT` is reported, with
the split whose two parts are each closest to rigid (:func:`best_split`). Skin motion raises the ratio too (half
the rigid groups with soft tissue in those draws), so the report names both readings: it is a question the data
leave open, and the skeleton is not called settled.

Before that report, the grouping splits the groups that *are* two segments (:func:`split_coherent`). What tells a
joint from skin is not how far B moves in A's pose but how: through a joint B turns as one rigid body, while skin
moves each marker on its own. Posed separately, A and B each keep only their own non-rigidity; posed as one, the
group adds B's rigid motion relative to A. The *coherence* of a split is that added residual per parameter a
second pose takes (6, or 5 for a pair, whose roll about its own line is free) over the parts' own residual per
degree of freedom: an F ratio, about 1 for one rigid body with independent noise, scale-free, so the same under
more noise or more skin wobble. Skin motion driven by a joint's angle moves a segment's markers together, in
part, and raised it to 3.4 at most over 67 single-segment groups of five or more markers with soft tissue (two
development draws of the independent skeleton generator, seeds 6464 and 5353; 1.25 at most over 149 without);
in 28 groups that merged two segments across a joint it was 1.65-21.9, and 4 or more in 16. A group of five or
more markers is split in two where the coherence of its best split (the one whose parts are each most rigid: the
least residual per degree of freedom) reaches :data:`COHERENCE_LIMIT`, and each part is checked again. Splits
below :data:`SURE_COHERENCE` are reported as open: a segment with strong skin motion driven by one joint could
come out split. Independent per-marker skin motion, however large, leaves the coherence near 1 (tests). A marker
alone cannot be told from a skin marker this way (its own motion is all the evidence), so parts have two
markers or more; computed points (virtual joint centres, rigid to round-off with their segment) are left out of
the test, which they would distort, and join the part they are most rigid with.
"""
from __future__ import annotations

import warnings

import numpy as np

from identcheck.estimate.noise import MIN_SAMPLES_PER_PAIR
from identcheck.geometry.poses import MIN_MARKERS, pose_noise_factor, refine_local
from identcheck.infer.body_frames import body_fixed, evenly_spaced
from identcheck.infer.separated_groups import spread_dendrogram

RATIO_LIMIT = 1.5
"""Smallest motion ratio reported (module docstring)."""
MIN_GROUP = MIN_MARKERS + 2
"""Smallest group checked: a posed part and at least two markers to see in its frame."""
MAX_FRAMES = 400
"""The check uses at most this many frames, evenly spread."""
MOVE_ROUNDS = 4
"""Most markers moved one at a time between the parts of a reported split (:func:`best_split`) ..."""
MOVE_MAX_GROUP = 16
"""... in groups of at most this many markers (each round tries every marker: bounded time on large groups)."""
COHERENCE_LIMIT = 4.0
"""Smallest coherence at which a group is split (module docstring)."""
SURE_COHERENCE = 6.0
"""Splits with a coherence below this are reported as a reading the data leave open."""
MIN_OTHER = 2
"""Fewest markers in the part that is not posed by itself in a split for the coherence."""
REFINE_STEPS = 3
"""Steps of the shape averaging behind a part's residual (:func:`part_residual`): the first frame's shape carries
that frame's noise into every pose, one step takes most of it out, and the coherence, a ratio of residuals, needs
the rest out too.
"""


def motion_ratio(xyz: np.ndarray, part_a: list, part_b: list, sigma_mm: float) -> float:
    """How much the markers `part_b` move in the pose of `part_a`, in units of what noise σ alone would do
    (module docstring). NaN when A has no pose or B is never seen with it."""
    try:
        poses, local, place = body_fixed(xyz, part_a, part_b)
    except ValueError:                                                     # A never seen whole in these frames
        return float("nan")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        d2 = np.sum((local - place) ** 2, axis=2)                          # NaN where unseen
        expected = 3.0 * sigma_mm ** 2 * (1.0 + pose_noise_factor(poses.local, np.nan_to_num(place)) ** 2)
        per_marker = np.nanmean(d2, axis=0) / expected
    return float(np.sqrt(np.nanmean(per_marker))) if np.isfinite(per_marker).any() else float("nan")


def part_residual(xyz: np.ndarray, part: list) -> tuple[np.ndarray, int, int]:
    """How far a part is from rigid, frame by frame.

    Returns
    -------
    rss : numpy.ndarray, shape (n_frames,)
        Sum of squared residuals of the part's best rigid placement (three or more markers: its shape averaged over
        the frames, :data:`REFINE_STEPS` steps of seed 001's eq. 5); for two markers, half the squared deviation of
        their distance from its mean (each marker takes half); 0 for one marker. NaN where a marker of the part is
        unseen.
    dof : int
        Residual degrees of freedom per frame: 3n − 6, 1 for two markers, 0 for one.
    params : int
        Parameters a pose of the part's own takes per frame: 6, 5 for two markers (roll about their line is free),
        3 for one (a free point).

    Raises
    ------
    ValueError
        Three or more markers never seen whole with a pose.
    """
    pts = xyz[:, part]
    seen = np.isfinite(pts).all(axis=(1, 2))
    if len(part) >= MIN_MARKERS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)      # a few steps by design: not converged
            _, poses = refine_local(pts, n_iter=REFINE_STEPS)
        rss = poses.rms ** 2 * len(part)
        return np.where(seen & poses.valid, rss, np.nan), 3 * len(part) - 6, 6
    if len(part) == 2:
        d = np.linalg.norm(pts[:, 0] - pts[:, 1], axis=1)
        return (d - np.nanmean(d)) ** 2 / 2.0, 1, 5
    return np.where(seen, 0.0, np.nan), 0, 3


def own_ratio(xyz: np.ndarray, part: list, sigma_mm: float) -> float:
    """How far one part is from rigid, in units of noise σ: the root of its residual per degree of freedom
    (:func:`part_residual`) over σ; 1 for a single marker; inf for a part never seen whole."""
    if len(part) < 2:
        return 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            rss, dof, _ = part_residual(xyz, part)
        except ValueError:                               # never seen whole in these frames: no evidence of rigidity
            return float("inf")
        r = float(np.sqrt(np.nanmean(rss) / dof) / sigma_mm)
    return r if np.isfinite(r) else float("inf")        # never posed (collinear, unseen): no evidence


def coherence(xyz: np.ndarray, part_a: list, part_b: list, union=None) -> tuple[float, float]:
    """How much better the group fits as two rigid bodies than as one, and how rigid the two are.

    Over the frames in which every marker of both parts is seen: the union's residual less the parts' own, per
    parameter B's own pose takes, over the parts' residual per degree of freedom (module docstring).

    Parameters
    ----------
    xyz : array, shape (n_frames, n_markers, 3)
    part_a, part_b : list of int
        A has three or more markers; B one or more.
    union : numpy.ndarray, optional
        :func:`part_residual` of A and B together, when already computed.

    Returns
    -------
    (float, float)
        The coherence (NaN with fewer than :data:`~identcheck.estimate.noise.MIN_SAMPLES_PER_PAIR` such frames) and
        the parts' residual per degree of freedom, mm² (inf when A has no pose or there are too few frames).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            ru = part_residual(xyz, sorted(part_a + part_b))[0] if union is None else union
            ra, dof_a, _ = part_residual(xyz, part_a)
        except ValueError:
            return float("nan"), float("inf")
        rb, dof_b, params = part_residual(xyz, part_b)
        ok = np.isfinite(ru) & np.isfinite(ra) & np.isfinite(rb)
        if ok.sum() < MIN_SAMPLES_PER_PAIR:
            return float("nan"), float("inf")
        own = float(np.mean(ra[ok] + rb[ok]))
        per_dof = own / (dof_a + dof_b)
        added = (float(np.mean(ru[ok])) - own) / params
    return (added / per_dof if per_dof > 0 else float("inf")), per_dof


def _tree_splits(spread: np.ndarray, columns: list, min_other: int) -> list:
    """The splits of the group's complete-linkage tree of pair spreads: each node against the rest, either side
    posed (three or more markers), the other side `min_other` or more."""
    kids, _, leaves, root = spread_dendrogram(spread, sorted(columns))
    out = []
    for node in kids.keys() | set(range(len(columns))):
        if node == root:
            continue
        inside = sorted(leaves[node])
        rest = [c for c in sorted(columns) if c not in inside]
        out += [(a, b) for a, b in ((inside, rest), (rest, inside)) if len(a) >= MIN_MARKERS and len(b) >= min_other]
    return out


def _moved(cost, score: float, a: list, b: list, min_other: int, rounds: int):
    """Markers moved one at a time between the parts while that lowers `cost` (at most `rounds` moves)."""
    for _ in range(rounds):
        moves = [(sorted(set(a) - {m}), sorted(set(b) | {m})) for m in a if len(a) > MIN_MARKERS] + \
                [(sorted(set(a) | {m}), sorted(set(b) - {m})) for m in b if len(b) > min_other]
        best = min(((cost(x, y), x, y) for x, y in moves), key=lambda s: s[0], default=None)
        if best is None or not best[0] < score:
            break
        score, a, b = best
    return score, a, b


def coherent_split(xyz: np.ndarray, spread: np.ndarray, columns: list):
    """The group's split whose parts are each most rigid, and its coherence.

    The splits of the group's complete-linkage tree (:func:`_tree_splits`) are scored by the parts' residual per
    degree of freedom (:func:`coherence`); markers are then moved one at a time between the parts of the best while
    that lowers it (groups of at most :data:`MOVE_MAX_GROUP`).

    Returns
    -------
    (float, list, list) or None
        The coherence and the posed part and the other (columns); None for a group of fewer than
        ``3 + MIN_OTHER`` markers, one never posed whole, or no split with enough frames.
    """
    columns = sorted(columns)
    if len(columns) < MIN_MARKERS + MIN_OTHER:
        return None
    try:
        union = part_residual(xyz, columns)[0]
    except ValueError:
        return None
    scores: dict = {}

    def scored(a, b):
        key = (tuple(a), tuple(b))
        if key not in scores:
            scores[key] = coherence(xyz, list(a), list(b), union)
        return scores[key]

    def cost(a, b):
        return scored(a, b)[1]

    splits = [(cost(a, b), a, b) for a, b in _tree_splits(spread, columns, MIN_OTHER)]
    splits = [s for s in splits if np.isfinite(s[0])]
    if not splits:
        return None
    score, a, b = min(splits, key=lambda s: s[0])
    _, a, b = _moved(cost, score, a, b, MIN_OTHER, MOVE_ROUNDS if len(columns) <= MOVE_MAX_GROUP else 0)
    value = scored(a, b)[0]
    return (value, a, b) if np.isfinite(value) else None


def split_coherent(xyz, spread: np.ndarray, groups: list, computed=()) -> tuple[list, list]:
    """Split every group whose best split reaches :data:`COHERENCE_LIMIT`, and check its parts again.

    Parameters
    ----------
    xyz : array, shape (n_frames, n_markers, 3)
        Marker positions, mm (at most :data:`MAX_FRAMES` frames, evenly spread, are used).
    spread : array, shape (n_markers, n_markers)
        Pair spreads, mm.
    groups : list of list of int
        The groups (marker columns).
    computed : collection of int
        Computed points: left out of the test, and put with the part whose markers keep the smallest largest
        spread to them.

    Returns
    -------
    groups : list of list of int
        The groups after splitting, each ascending.
    splits : list of (float, list, list)
        Each split made: its coherence and the two parts (columns, computed points included), in the order made.
    """
    xyz = evenly_spaced(np.asarray(xyz, dtype=float), MAX_FRAMES)
    S = np.nan_to_num(np.asarray(spread, dtype=float), nan=np.inf)
    computed = set(computed)
    todo, done, splits = [sorted(g) for g in groups], [], []
    while todo:                                          # each split leaves smaller groups: it ends
        g = todo.pop(0)
        found = coherent_split(xyz, spread, [c for c in g if c not in computed])
        if found is None or not found[0] >= COHERENCE_LIMIT:
            done.append(g)
            continue
        value, a, b = found
        for c in (c for c in g if c in computed):
            (a if S[c, a].max() <= S[c, b].max() else b).append(c)
        a, b = sorted(a), sorted(b)
        splits.append((value, a, b))
        todo += [a, b]
    return done, splits


def best_split(xyz: np.ndarray, spread: np.ndarray, columns: list, sigma_mm: float):
    """Whether one group moves inside beyond the noise, and where it splits.

    Every split of the group's complete-linkage tree (a node against the rest, either side posed) gets its motion
    ratio. The largest says whether the group is rigid. When it reaches :data:`RATIO_LIMIT`, the split reported is
    the one whose two parts are each closest to rigid (:func:`own_ratio`): a pose of markers from both segments is
    itself distorted, so the largest ratio often comes from such a mixed part, and the two segments' own split
    can show less than the limit. When the segments hardly move, noise decides the tree's order and their split
    need not be among its nodes, so markers are then moved one at a time between the parts while that brings both
    closer to rigid.

    Returns
    -------
    (float, list, list) or None
        The largest ratio and the reported split's posed part and other part (columns); None when the group is too
        small to split into a posed part and two more markers, or no split has a finite ratio.
    """
    if len(columns) < MIN_GROUP:
        return None
    splits = []
    for a, b in _tree_splits(spread, columns, 2):
        r = motion_ratio(xyz, a, b, sigma_mm)
        if np.isfinite(r):
            splits.append((r, a, b))
    if not splits:
        return None
    largest = max(s[0] for s in splits)
    if largest < RATIO_LIMIT:
        _, a, b = max(splits, key=lambda s: s[0])
        return largest, a, b
    own: dict = {}

    def rigidity(part):
        key = tuple(part)
        if key not in own:
            own[key] = own_ratio(xyz, part, sigma_mm)
        return own[key]

    def worse(a, b):
        return max(rigidity(a), rigidity(b))

    score, a, b = min(((worse(s[1], s[2]), s[1], s[2]) for s in splits), key=lambda s: s[0])
    _, a, b = _moved(worse, score, a, b, 2, MOVE_ROUNDS if len(columns) <= MOVE_MAX_GROUP else 0)
    return largest, a, b


def check_groups(xyz, labels, groups: dict, spread: np.ndarray, sigma_mm: float) -> list:
    """The groups that may be two segments.

    Parameters
    ----------
    xyz : array, shape (n_frames, n_markers, 3)
        Marker positions, mm.
    labels : sequence of str
    groups : dict of str to sequence of str
        Group name → its markers.
    spread : array, shape (n_markers, n_markers)
        Pair spreads, mm (:func:`identcheck.infer.grouping.pair_statistics`).
    sigma_mm : float
        Marker noise per coordinate, mm.

    Returns
    -------
    list of dict
        ``{"segment", "parts": [A, B], "motion_ratio", "note"}`` for each group whose best split reaches
        :data:`RATIO_LIMIT`.
    """
    if not (sigma_mm and np.isfinite(sigma_mm) and sigma_mm > 0):
        return []
    xyz = np.asarray(xyz, dtype=float)
    xyz = evenly_spaced(xyz, MAX_FRAMES)
    index = {m: i for i, m in enumerate(labels)}
    out = []
    for name, markers in groups.items():
        found = best_split(xyz, spread, [index[m] for m in markers], sigma_mm)
        if found is None or found[0] < RATIO_LIMIT:
            continue
        r, a, b = found
        parts = [[labels[i] for i in a], [labels[i] for i in b]]
        out.append({"segment": name, "parts": parts, "motion_ratio": r,   # the largest: the parts' own may be less
                    "note": f"{', '.join(parts[1])} move in the pose of {', '.join(parts[0])} {r:.3g} times as much "
                            f"as marker noise ({sigma_mm:.3g} mm) alone would move them: {name} may be two segments "
                            "joined by a joint that hardly moves in this trial, or its markers move on the skin"})
    return out
