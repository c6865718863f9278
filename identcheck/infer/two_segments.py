"""Groups that may be two segments: markers that move relative to the rest of their group more than noise allows.

Markers group together when their distances stay within a tolerance that allows for noise and skin wobble, so two
segments joined by a joint that hardly moves in the trial (or whose markers lie near a hinge's axis) can come out
as one group. Measured on held-out random skeletons, such merges were most of the wrong trees the tool called
settled.

With the marker noise σ known, a rigid group can be checked against it: seen in the pose of some of its markers
(part A, three or more), each other marker (part B, one or more) scatters about its body-fixed place by σ²(1 + f²)
per coordinate, f being how much A's own pose noise adds there
(:func:`identcheck.geometry.poses.pose_noise_factor`). The *motion ratio* of a split is the root of the mean, over
B's markers and the frames, of the squared distance from that place over 3σ²(1 + f²): about 1 for a rigid group
whatever the split (0.85-1.15 for 95 % of 172 rigid groups of five or more markers in two development draws of the
independent skeleton generator), larger when B turns relative to A. For groups of four, split three and one, the
median was 1.02 and 6 of 490 rigid groups without soft tissue reached 1.5 (two development draws, 6969 and 7272); a
one-marker segment near a joint that joined its neighbour's three markers is seen only this way. The splits tried
are those of the group's own complete-linkage tree of pair spreads (each node against the rest, either side posed).
A group whose largest ratio is at least :data:`RATIO_LIMIT` is reported, with the split whose two parts are each
closest to rigid (:func:`best_split`). So is a group whose split parts are each rigid while one moves in the other's
pose clearly more than either departs from rigid on its own (:data:`RELATIVE_LIMIT`). Skin motion raises the ratio
too (half the rigid groups with soft tissue in those draws), so the report names both readings: it is a question the
data leave open, and the skeleton is not called settled.
"""
from __future__ import annotations

import warnings

import numpy as np

from identcheck.geometry.poses import MIN_MARKERS, pose_noise_factor, refine_local
from identcheck.infer.body_frames import body_fixed, evenly_spaced
from identcheck.infer.separated_groups import spread_dendrogram

RATIO_LIMIT = 1.5
"""Smallest motion ratio reported (module docstring)."""
RELATIVE_LIMIT = 1.4
"""... or the smallest ratio of the reported split's motion ratio to the larger of its two parts' own departures
from rigid (:func:`own_ratio`) that is reported: two parts each as rigid as noise allows, one moving in the other's
pose beyond that. Skin motion raises both, so this sees a merge that wobbling skin hides from the plain ratio. On
development draw 6868 of the independent skeleton generator, 99 % of 125 groups of one segment stayed below 1.38
(largest 1.48); a merge of two 4- and 2-marker segments across a hinge turning 26 deg reached 1.51 with a plain
ratio of 1.49."""
MAX_NOISE_FACTOR = 4.0
"""A part B of one marker where A's pose amplifies the noise more than this (:func:`pose_noise_factor`) is not
judged: there, far from a thin triangle of three markers, the linear amplification understates the pose's noise
(rigid groups of four with white noise reached ratios of 1.4-1.8 at amplifications of 4.6-12), and one marker's
ratio has no others to average that with. Parts of two or more markers are judged wherever they lie, as before."""
MIN_GROUP = MIN_MARKERS + 1
"""Smallest group checked: a posed part and a marker to see in its frame."""
MAX_FRAMES = 400
"""The check uses at most this many frames, evenly spread."""
MOVE_ROUNDS = 4
"""Most markers moved one at a time between the parts of a reported split (:func:`best_split`) ..."""
MOVE_MAX_GROUP = 16
"""... in groups of at most this many markers (each round tries every marker: bounded time on large groups)."""


def motion_ratio(xyz: np.ndarray, part_a: list, part_b: list, sigma_mm: float) -> float:
    """How much the markers `part_b` move in the pose of `part_a`, in units of what noise σ alone would do
    (module docstring). NaN when A has no pose, B is never seen with it, or B is one marker where A's pose
    amplifies the noise beyond :data:`MAX_NOISE_FACTOR`."""
    try:
        poses, local, place = body_fixed(xyz, part_a, part_b)
    except ValueError:                                                     # A never seen whole in these frames
        return float("nan")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        d2 = np.sum((local - place) ** 2, axis=2)                          # NaN where unseen
        factor = pose_noise_factor(poses.local, np.nan_to_num(place))
        expected = 3.0 * sigma_mm ** 2 * (1.0 + factor ** 2)
        per_marker = np.nanmean(d2, axis=0) / expected
        if len(part_b) == 1:
            per_marker = np.where(factor <= MAX_NOISE_FACTOR, per_marker, np.nan)
    return float(np.sqrt(np.nanmean(per_marker))) if np.isfinite(per_marker).any() else float("nan")


def own_ratio(xyz: np.ndarray, part: list, sigma_mm: float) -> float:
    """How far one part is from rigid, in units of noise σ.

    For three or more markers, the RMS residual of their pose (on their shape averaged over the frames, one step of
    seed 001's eq. 5) over the σ √((3n − 6)/n) that noise alone leaves; for two, their distance's standard
    deviation over σ √2; 1 for a single marker; inf for a part never seen whole.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        if len(part) >= MIN_MARKERS:
            try:                                         # the first frame's shape carries that frame's noise:
                _, poses = refine_local(xyz[:, part], n_iter=1)    # one averaging step takes most of it out
            except ValueError:                           # never seen whole in these frames: no evidence of rigidity
                return float("inf")
            n = len(part)
            r = float(np.sqrt(np.nanmean(poses.rms ** 2) / (sigma_mm ** 2 * (3 * n - 6) / n)))
            return r if np.isfinite(r) else float("inf")   # never posed (collinear, unseen): no evidence
        if len(part) == 2:
            d = np.linalg.norm(xyz[:, part[0]] - xyz[:, part[1]], axis=1)
            r = float(np.nanstd(d) / (sigma_mm * np.sqrt(2.0)))
            return r if np.isfinite(r) else float("inf")
    return 1.0


def best_split(xyz: np.ndarray, spread: np.ndarray, columns: list, sigma_mm: float):
    """Whether one group moves inside beyond the noise, and where it splits.

    Every split of the group's complete-linkage tree (a node against the rest, either side posed; a node may be one
    marker) gets its motion ratio. The largest says whether the group is rigid. When it reaches
    :data:`RATIO_LIMIT`, the split reported is the one whose two parts are each closest to rigid
    (:func:`own_ratio`; among splits with two or more markers on each side where the group has them): a pose of
    markers from both segments is itself distorted, so the largest ratio often comes from such a mixed part, and
    the two segments' own split can show less than the limit. When the segments hardly move, noise decides the
    tree's order and their split need not be among its nodes, so markers are then moved one at a time between the
    parts while that brings both closer to rigid.

    Returns
    -------
    (float, list, list, float) or None
        The largest ratio, the reported split's posed part and other part (columns), and that split's motion ratio
        over the larger of its parts' own departures from rigid (:data:`RELATIVE_LIMIT`); None when the group is too
        small to split into a posed part and one more marker, or no split has a finite ratio.
    """
    if len(columns) < MIN_GROUP:
        return None
    kids, _, leaves, root = spread_dendrogram(spread, sorted(columns))
    splits = []
    for node in kids.keys() | set(range(len(columns))):
        if node == root:
            continue
        inside = leaves[node]
        rest = [c for c in sorted(columns) if c not in inside]
        for a, b in ((inside, rest), (rest, inside)):
            if len(a) >= MIN_MARKERS and len(b) >= 1:
                r = motion_ratio(xyz, a, b, sigma_mm)
                if np.isfinite(r):
                    splits.append((r, sorted(a), sorted(b)))
    if not splits:
        return None
    largest = max(s[0] for s in splits)
    # a part of one marker is rigid by definition and would win every comparison below: the split reported has
    # two or more on each side wherever the group allows it (every marker still counts for `largest`)
    least_b = 2 if any(len(s[2]) >= 2 for s in splits) else 1
    splits = [s for s in splits if len(s[2]) >= least_b]
    own: dict = {}

    def rigidity(part):
        key = tuple(part)
        if key not in own:
            own[key] = own_ratio(xyz, part, sigma_mm)
        return own[key]

    def worse(a, b):
        return max(rigidity(a), rigidity(b))

    score, a, b = min(((worse(s[1], s[2]), s[1], s[2]) for s in splits), key=lambda s: s[0])
    for _ in range(MOVE_ROUNDS if len(columns) <= MOVE_MAX_GROUP else 0):   # the tree's splits need not hold
        moves = [(sorted(set(a) - {m}), sorted(set(b) | {m})) for m in a if len(a) > MIN_MARKERS] + \
                [(sorted(set(a) | {m}), sorted(set(b) - {m})) for m in b if len(b) > least_b]
        best = min(((worse(x, y), x, y) for x, y in moves), key=lambda s: s[0], default=None)
        if best is None or best[0] >= score:
            break
        score, a, b = best
    cross = motion_ratio(xyz, a, b, sigma_mm)
    if len(b) >= MIN_MARKERS:
        cross = np.nanmax([cross, motion_ratio(xyz, b, a, sigma_mm)])
    relative = float(cross / score) if np.isfinite(cross) and np.isfinite(score) and score > 0 else float("nan")
    return largest, a, b, relative


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
        ``{"segment", "parts": [A, B], "motion_ratio", "relative_ratio", "note"}`` for each group whose largest
        motion ratio reaches :data:`RATIO_LIMIT` or whose reported split's relative ratio reaches
        :data:`RELATIVE_LIMIT`.
    """
    if not (sigma_mm and np.isfinite(sigma_mm) and sigma_mm > 0):
        return []
    xyz = np.asarray(xyz, dtype=float)
    xyz = evenly_spaced(xyz, MAX_FRAMES)
    index = {m: i for i, m in enumerate(labels)}
    out = []
    for name, markers in groups.items():
        found = best_split(xyz, spread, [index[m] for m in markers], sigma_mm)
        if found is None or not (found[0] >= RATIO_LIMIT or found[3] >= RELATIVE_LIMIT):
            continue
        r, a, b, rel = found
        parts = [[labels[i] for i in a], [labels[i] for i in b]]
        why = (f"{', '.join(parts[1])} move in the pose of {', '.join(parts[0])} {r:.3g} times as much as marker "
               f"noise ({sigma_mm:.3g} mm) alone would move them" if r >= RATIO_LIMIT else
               f"{', '.join(parts[1])} and {', '.join(parts[0])} each stay rigid within the noise, but move relative "
               f"to each other {rel:.3g} times as much as either part departs from rigid on its own")
        out.append({"segment": name, "parts": parts, "motion_ratio": r,   # the largest: the parts' own may be less
                    "relative_ratio": None if not np.isfinite(rel) else rel,
                    "note": f"{why}: {name} may be two segments joined by a joint that hardly moves in this trial, or "
                            "its markers move on the skin"})
    return out
