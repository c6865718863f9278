"""Swapped marker labels, caught before a fit: a joint fitted through frames where two markers' labels are
exchanged is silently wrong, and real recordings do contain such spans (examples/real_diagnose_report.md).

Markers on one segment keep their distances apart. The model-free detector of ``diagnose``
(:func:`detect`, which ``diagnose``'s ``marker_swap`` effect also uses) compares, frame by frame, those distances as
labelled and as exchanged with their medians. A span that fits clearly better exchanged is judged
against the majority labelling, so the span is the minority. :func:`screen` leaves that span out for
the two markers, so the fit sees only the frames labelled like the rest of the trial, and it says so.
The noise scale is the distances' whole-trial scatter (skin motion included), so only exchanges far
beyond the segment's own deformation count. A wrong pair corrupts the distances of its partners too, so its span is
exchanged back before the next search (the strongest detection first), which keeps those echoes from being reported.
Two markers whose distances to the rest of their segment are alike (the base of a near-isosceles triangle, a pair
mirror-symmetric about the plane of the others) exchange without changing a distance; the segment's pose then
turns by a half turn at both ends of the span, and :func:`flips` finds them from that. Two markers alone on a
segment keep their one distance, and a swap beginning or ending in a gap shows the distances only on one side of it:
each marker's trajectory then goes on from where the other's was last seen, and :func:`exchanges` reads that.
Where only one of the two markers is seen, its own distances are read both ways (:func:`swap_costs`).
The input file is not touched.
"""
from __future__ import annotations

import warnings

import numpy as np

from identcheck.errors import InputError
from identcheck.estimate.noise import noise_floor
from identcheck.geometry.poses import poses_segment, reference_shape, segment_poses
from identcheck.skeleton import Skeleton

MIN_RUN = 3          # frames
MAX_HOLE = 2         # frames of doubt (gaps, ties) bridged inside a run


def _partners(chain, col: int, exclude: set) -> np.ndarray:
    seg = chain.marker_seg[col]
    return np.array([k for k in chain.seg_markers[seg] if k not in exclude], dtype=int)


class _Distances:
    """Each marker's distances to the other markers of its segment (F, n) and their medians over frames, computed
    once per search and shared by every pair it is tested in (the medians are what make the search slow)."""

    def __init__(self, data: np.ndarray, chain):
        self.data, self.chain, self._own, self._padded = data, chain, {}, None

    def to(self, a: int, ks: np.ndarray) -> np.ndarray:
        return np.linalg.norm(self.data[:, [a]] - self.data[:, ks], axis=2)

    def own(self, a: int, exclude: set):
        """(partner columns, their distances' medians (n,)) of marker `a`, its partners being the other markers of its
        segment not in `exclude`."""
        ks = _partners(self.chain, a, exclude | {a})
        key = (a, tuple(ks))
        if key not in self._own:
            self._own[key] = (ks, np.nanmedian(self.to(a, ks), axis=0) if len(ks) else np.zeros(0))
        return self._own[key]

    def padded(self) -> tuple:
        """Every marker's partners on its segment, their distances' medians and the squared misfits of its distances
        to them, padded with NaN (columns -1) to the most partners W: (columns (M, W), medians (M, W), misfits
        (F, M, W), partner counts (M,)), computed once."""
        if self._padded is None:
            M, F = self.chain.n_markers, len(self.data)
            parts = [self.own(a, set()) for a in range(M)]
            width = max([len(P) for P, _ in parts] + [1])
            cols, meds = np.full((M, width), -1), np.full((M, width), np.nan)
            misfit = np.full((F, M, width), np.nan)
            for a, (P, D) in enumerate(parts):
                if len(P):
                    cols[a, :len(P)], meds[a, :len(P)] = P, D
                    misfit[:, a, :len(P)] = (self.to(a, P) - D) ** 2
            self._padded = cols, meds, misfit, np.array([len(P) for P, _ in parts])
        return self._padded


def swap_costs(data: np.ndarray, chain, i: int, j: int, dists: _Distances | None = None):
    """Per-frame misfit of the within-segment distances with labels i, j as given and exchanged (F,), mm².

    Where both markers are seen, each one's distances to its partners are read as its own and as the other's. Where
    only one is seen (a swap often begins or ends in a gap), its distances alone are read both ways, their mean
    misfit per distance scaled to the pair's number of distances so that both kinds of frame weigh alike; NaN
    where neither is seen, or where the seen one has no partner seen on either side."""
    dists = dists or _Distances(data, chain)
    Pi, Di = dists.own(i, {j})
    Pj, Dj = dists.own(j, {i})
    n = len(Pi) + len(Pj)
    if n == 0:
        return None, None
    own_i, own_j = (dists.to(i, Pi) - Di) ** 2, (dists.to(j, Pj) - Dj) ** 2
    i_as_j, j_as_i = (dists.to(i, Pj) - Dj) ** 2, (dists.to(j, Pi) - Di) ** 2
    seen = np.all(np.isfinite(data[:, [i, j]]), axis=2)
    return _kept_and_swapped(own_i, own_j, i_as_j, j_as_i, n, seen[:, 0], seen[:, 1])


def _kept_and_swapped(own_i, own_j, i_as_j, j_as_i, n, seen_i, seen_j) -> tuple[np.ndarray, np.ndarray]:
    """The per-frame misfits as labelled and exchanged (:func:`swap_costs`) from the squared misfits of i's and j's
    distances to their own partners (``own_i``, ``own_j``) and to the other's (``i_as_j``, ``j_as_i``), the partner
    axis last (NaN: unseen, left out), `n` the pair's distances and where each marker is seen; any leading shape
    that broadcasts (one pair, (F,); i against many j, (F, J))."""
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)            # means of frames with no partner seen: NaN
        keep = np.nansum(own_i, axis=-1) + np.nansum(own_j, axis=-1)
        swap = np.nansum(j_as_i, axis=-1) + np.nansum(i_as_j, axis=-1)
        only_i = n * np.nanmean(own_i, axis=-1), n * np.nanmean(i_as_j, axis=-1)
        only_j = n * np.nanmean(own_j, axis=-1), n * np.nanmean(j_as_i, axis=-1)
    keep, swap = np.broadcast_arrays(keep, swap)
    keep, swap = keep.copy(), swap.copy()
    for alone, (k, s) in ((seen_i & ~seen_j, only_i), (seen_j & ~seen_i, only_j)):
        keep[alone], swap[alone] = np.broadcast_to(k, alone.shape)[alone], np.broadcast_to(s, alone.shape)[alone]
    neither = ~seen_i & ~seen_j
    keep[neither], swap[neither] = np.nan, np.nan
    return keep, swap


def swap_costs_across(data: np.ndarray, chain, i: int, js: list, dists: _Distances) -> dict:
    """:func:`swap_costs` of marker `i` with each marker of `js`, all on segments other than `i`'s, at once: j -> (keep,
    swap), the same numbers (j without a partner on either side: left out, as :func:`swap_costs` gives None).

    Why: the label screen tests every pair of markers, and one pair at a time cost about a millisecond of NumPy calls
    on a few distances (a 56-marker body: 1540 pairs, 1.6 s a round of ``diagnose``). Markers on other segments keep
    their own partners whatever `i` is, so their distances to their partners are read once per marker and `i`'s
    distances to every marker once per `i`; the distances of each j to `i`'s partners are taken for all j together.
    Partner lists of unequal lengths are padded with NaN, which the NaN-ignoring sums and means leave out."""
    if not js:
        return {}
    cols_all, meds_all, misfit, count = dists.padded()
    Pi, Di = cols_all[i, :count[i]], meds_all[i, :count[i]]
    cols, meds, own_j = cols_all[js], meds_all[js], misfit[:, js]                # (J, W), (J, W), (F, J, W)
    pad = cols < 0
    to_i = np.linalg.norm(data[:, [i]] - data, axis=2)                            # (F, M): i to every marker
    with np.errstate(invalid="ignore"):
        i_as_j = np.where(pad, np.nan, (to_i[:, np.where(pad, 0, cols)] - meds) ** 2)             # (F, J, W)
        j_as_i = (np.linalg.norm(data[:, js][:, :, None] - data[:, None, Pi], axis=3) - Di) ** 2   # (F, J, n_i)
    n = count[i] + count[js]
    seen_i = np.all(np.isfinite(data[:, i]), axis=1)[:, None]
    seen_j = np.all(np.isfinite(data[:, js]), axis=2)
    keep, swap = _kept_and_swapped(misfit[:, i, None, :count[i]], own_j, i_as_j, j_as_i, n, seen_i, seen_j)
    return {j: (keep[:, k], swap[:, k]) for k, j in enumerate(js) if n[k] > 0}


def longest_run(flag: np.ndarray, doubt: np.ndarray) -> tuple[int, int]:
    """First and last frame of the longest run of `flag`, bridging holes of at most MAX_HOLE `doubt`
    frames; (-1, -1) if none."""
    best, start, last_true, holes = (-1, -1), None, None, 0
    for f in range(len(flag) + 1):
        if f < len(flag) and flag[f]:
            start = f if start is None else start
            last_true, holes = f, 0
        elif start is not None and f < len(flag) and doubt[f] and holes < MAX_HOLE:
            holes += 1
        else:
            if start is not None and (best[0] < 0 or last_true - start > best[1] - best[0]):
                best = (start, last_true)
            start, holes = None, 0
    return best


def detect(data: np.ndarray, chain, sigma_mm: float, n_obs: int) -> list:
    """Label swaps the within-segment distances show, strongest first: dicts with the two columns, the
    frame span (first, last), the evidence ``gain`` (log-likelihood gain net of a BIC penalty for 3
    parameters), the per-frame misfits as labelled (``keep``) and exchanged (``swap``), mm², and the
    margin ``clear`` a frame's improvement had to exceed. A span needs :data:`MIN_RUN` frames showing both markers
    (where one alone is seen, two markers with alike distances, as in a cluster, read as exchanged by chance: a real
    walking trial's shank over three frames of a gap)."""
    sig2, pen = sigma_mm ** 2, np.log(max(n_obs, 2))
    out = []
    dists = _Distances(data, chain)
    seg = chain.marker_seg
    for i in range(chain.n_markers):
        across = swap_costs_across(data, chain, i, [j for j in range(i + 1, chain.n_markers) if seg[j] != seg[i]],
                                   dists)
        for j in range(i + 1, chain.n_markers):
            keep, swap = across.get(j, (None, None)) if seg[j] != seg[i] else swap_costs(data, chain, i, j, dists)
            if keep is None:
                continue
            n_terms = len(_partners(chain, i, {i, j})) + len(_partners(chain, j, {i, j}))
            clear = 2 * sig2 * n_terms * 9          # well beyond the distances' own noise
            better = (keep - swap > clear)
            if not np.any(better):
                continue
            doubt = ~np.isfinite(keep) | (np.abs(keep - swap) <= clear)
            a, b = longest_run(np.nan_to_num(better, nan=0).astype(bool), doubt)
            if a < 0 or b - a + 1 < MIN_RUN:
                continue
            both = np.all(np.isfinite(data[a:b + 1, [i, j]]), axis=(1, 2))
            if np.sum(better[a:b + 1] & both) < MIN_RUN:
                continue        # frames showing one marker only extend a run; alone they read too little
            gain = np.nansum((keep - swap)[a:b + 1]) / (2 * sig2) - 3 * pen
            if gain > 0:
                out.append({"cols": (i, j), "span": (int(a), int(b)), "gain": float(gain), "keep": keep, "swap": swap,
                            "clear": float(clear)})
    return sorted(out, key=lambda d: -d["gain"])


FLIP_DEG = 90.0
"""A segment that turns by more than this between two consecutive frames with a pose has been flipped by its
labels, not moved: 90 deg per frame is 9000 deg/s at 100 Hz (and still 2700 deg/s at 30 Hz)."""


SHAPE_TOL = 4.0
"""An exchange that removes a flip must leave the segment's markers fitting its shape within this many times
their median misfit over the trial; otherwise it only trades one distortion for another (a marker swapped with
another segment's leaves its own segment distorted, and exchanging two of that segment's markers does not fix it)."""


def _angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """The angles between rotations (..., 3, 3), deg; NaN rotations give NaN (which compares False)."""
    cos = (np.einsum("...ji,...ji->...", Ra, Rb) - 1) / 2                 # (trace(Raᵀ Rb) − 1) / 2
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _turns(poses_R: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(frames with a pose (n,), the angle turned from the previous such frame (n,), deg; the first gets 0)."""
    idx = np.flatnonzero(valid)
    R = poses_R[idx]
    return idx, np.concatenate([[0.0], _angle_deg(R[:-1], R[1:])])


def spans_between(changes, n_frames: int, bounds=()) -> list:
    """The spans (first, last) a labelling may be wrong over, given the frames where it changes over: with one
    change, the shorter side of it (the majority labelling is kept), each side ending at the nearest of `bounds`
    (frames where the labelling may have changed over unseen) or else at the trial's end; with more, every span
    between two of them (the trial's two ends being labelled alike)."""
    if len(changes) == 1:
        t = int(changes[0])
        lo = max((int(f) for f in bounds if f < t), default=0)
        hi = min((int(f) for f in bounds if f > t), default=n_frames)
        return [min([(lo, t - 1), (t, hi - 1)], key=lambda ab: ab[1] - ab[0])]
    edges = [0] + [int(f) for f in changes] + [n_frames]
    return [(edges[k], edges[k + 1] - 1) for k in range(1, len(edges) - 2)]


def flips(data: np.ndarray, chain) -> list:
    """Label swaps that the segment's pose shows and its distances do not.

    Two markers whose distances to the rest of their segment are alike (the base of a near-isosceles triangle, a
    pair mirror-symmetric about the plane of the others) exchanged over a span turn the segment by about a half
    turn at both ends of the span, while the within-segment distances barely change (:func:`detect` cannot see
    it). Per segment with three markers or more: the frames where its pose jumps by more than :data:`FLIP_DEG`.
    Every span between two jumps, or with a single jump the shorter side of it (the majority labelling is kept),
    is a candidate, with the pair of the segment's markers whose exchange there makes both of its ends turn less
    than that and fits the segment's shape best (within :data:`SHAPE_TOL`). Returns dicts like :func:`detect`'s
    without ``gain``: ``cols``, ``span``, ``keep``, ``swap``."""
    F, out = data.shape[0], []
    for seg in chain.segments:
        idx = list(chain.seg_markers[seg])
        if len(idx) < 3:
            continue
        pts = data[:, idx]
        try:
            local = reference_shape(pts)
        except ValueError:
            continue
        poses = segment_poses(pts, local)
        frames, turn = _turns(poses.R, poses.valid)
        jumps = frames[turn > FLIP_DEG]
        if not len(jumps) or len(jumps) > 20:            # none, or a segment too ill-posed to read
            continue
        before = {int(q): int(frames[k - 1]) for k, q in zip(np.flatnonzero(turn > FLIP_DEG), jumps)}
        # an exchange must leave the markers fitting the segment's shape as well as its frames usually do
        shape_tol = SHAPE_TOL * float(np.nanmedian(poses.rms)) + 1e-9
        for a, b in spans_between(jumps, F):
            # the pairs of frames across the span's ends (the frame before a jump: the last one with a pose)
            ends = [(before[a], a)] if a in before else []
            ends += [(before[b + 1], b + 1)] if b + 1 in before else []
            rows = sorted({f for pair in ends for f in pair})
            at = {f: k for k, f in enumerate(rows)}
            inside = (np.array(rows) >= a) & (np.array(rows) <= b)
            best = None
            for ii in range(len(idx)):
                for jj in range(ii + 1, len(idx)):
                    swapped = pts[rows].copy()
                    swapped[np.ix_(inside, [ii, jj])] = swapped[np.ix_(inside, [jj, ii])]
                    near = segment_poses(swapped, local)
                    misfit = float(np.max(near.rms))        # NaN (no pose) compares False below
                    if (all(_angle_deg(near.R[at[p]], near.R[at[q]]) <= FLIP_DEG for p, q in ends)
                            and misfit <= shape_tol and (best is None or misfit < best[0])):
                        best = (misfit, idx[ii], idx[jj])
            if best is not None:                    # the exchange that leaves the segment's own shape intact
                _, i, j = best
                keep, swap = swap_costs(data, chain, i, j)
                out.append({"cols": (min(i, j), max(i, j)), "span": (int(a), int(b)), "keep": keep, "swap": swap})
    return out


JUMP_RATIO = 10.0
"""A frame where two markers' positions continue this many times better exchanged than as labelled (squared
distances from where each was last seen) is where their labels changed over."""
LOOKBACK = 10
"""Frames back to the last one showing both markers that a change of labels is read across (a short gap)."""


def _last_seen(seen: np.ndarray) -> np.ndarray:
    """For each frame, the last frame before it where `seen` holds (F,); -1 before the first."""
    idx = np.where(seen, np.arange(len(seen)), -1)
    return np.concatenate([[-1], np.maximum.accumulate(idx)[:-1]])


def _both_continue(xi, xj, seen_i, seen_j, keep, swap) -> tuple[np.ndarray, np.ndarray]:
    """(Frames where markers i and j, both seen, continue from their last common frame (at most :data:`LOOKBACK`
    back) :data:`JUMP_RATIO` times better exchanged than as labelled, those last common frames); `keep` and `swap`
    get the squared steps."""
    both = np.flatnonzero(seen_i & seen_j)
    if len(both) < 2:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    now, last = both[1:], both[:-1]
    keep[now] = np.sum((xi[now] - xi[last]) ** 2 + (xj[now] - xj[last]) ** 2, axis=1)
    swap[now] = np.sum((xi[now] - xj[last]) ** 2 + (xj[now] - xi[last]) ** 2, axis=1)
    turned = (now - last <= LOOKBACK) & (JUMP_RATIO * swap[now] < keep[now])
    return now[turned], last[turned]


def _handovers(xa, xb, seen_a, seen_b, apart2: float, keep, swap) -> np.ndarray:
    """Frames where marker b has just vanished (last seen at most :data:`MAX_HOLE` + 1 frames back) and marker a,
    seen for the first time since, sits :data:`JUMP_RATIO` times closer (squared) to where b was last than to where
    a itself was last (within :data:`LOOKBACK`; when a was not seen so recently, than the two markers' usual squared
    distance `apart2`): the trajectory goes on under the other label, as when labels change over in a gap."""
    last_a, last_b = _last_seen(seen_a), _last_seen(seen_b)
    frames = np.arange(len(seen_a))
    # the first frame showing a since b was last seen
    at = np.flatnonzero(seen_a & ~seen_b & (last_b >= 0) & (frames - last_b <= MAX_HOLE + 1) & (last_a <= last_b))
    if not len(at):
        return at
    to_b = np.sum((xa[at] - xb[last_b[at]]) ** 2, axis=1)
    recent = (last_a[at] >= 0) & (at - last_a[at] <= LOOKBACK)
    to_a = np.where(recent, np.sum((xa[at] - xa[np.maximum(last_a[at], 0)]) ** 2, axis=1), apart2)
    keep[at], swap[at] = to_a, to_b
    return at[JUMP_RATIO * to_b < to_a]


def _unseen_changes(seen_i: np.ndarray, seen_j: np.ndarray) -> list:
    """Frames where the labels of markers i and j may have changed over unseen: in each stretch between two frames
    showing both more than :data:`LOOKBACK` apart, the last frame at which neither label's trajectory runs on from
    the frame before (each is unseen there, or seen again after a gap). A change anywhere earlier in the stretch
    where both are unseen moves nothing; a change later would show as a jump in a label's own trajectory."""
    both = np.flatnonzero(seen_i & seen_j)
    out = []
    for last, now in zip(both[:-1], both[1:]):
        if now - last > LOOKBACK:
            f = np.arange(last + 1, now + 1)
            free = (~seen_i[f] | ~seen_i[f - 1]) & (~seen_j[f] | ~seen_j[f - 1])
            if free.any():
                out.append(int(f[free][-1]))
    return out


def exchanges(data: np.ndarray, chain) -> list:
    """Label swaps read from the markers' continuity: where labels change over, each marker's position continues
    from where the other was last seen. Two markers alone on a segment keep their one distance when exchanged (an
    anatomical thigh's lateral marker and epicondyle, exchanged over 190 frames, were named as skin on the thigh),
    and a swap that begins or ends in a gap shows the distances only on one side of it (a thigh and a shank marker
    exchanged from inside a gap were named as skin on both segments).

    For every pair of markers, a change of labels is read at the frames where both are seen and their squared steps
    from their last common frame (at most :data:`LOOKBACK` back) are :data:`JUMP_RATIO` times smaller exchanged
    than as labelled, and at the frames where one has just vanished and the other sits where it was last
    (:func:`_handovers`). The spans between such frames are the candidates as in :func:`flips` (with one, the
    shorter side, a side ending where the labels may have changed over unseen, in a long gap of both:
    :func:`_unseen_changes`). Returns dicts like :func:`flips`', ``keep`` and ``swap`` being those squared steps,
    mm², per frame."""
    F, out = data.shape[0], []
    seen = np.all(np.isfinite(data), axis=2)
    for i in range(chain.n_markers):
        for j in range(i + 1, chain.n_markers):
            both = seen[:, i] & seen[:, j]
            if both.sum() < 2 * MIN_RUN:
                continue
            xi, xj = data[:, i], data[:, j]
            apart2 = float(np.median(np.sum((xi[both] - xj[both]) ** 2, axis=1)))
            keep, swap = np.full(F, np.nan), np.full(F, np.nan)
            handed = np.union1d(_handovers(xi, xj, seen[:, i], seen[:, j], apart2, keep, swap),
                                _handovers(xj, xi, seen[:, j], seen[:, i], apart2, keep, swap))
            now, last = _both_continue(xi, xj, seen[:, i], seen[:, j], keep, swap)
            # a change read from both across frames where a handover was read is that same change, read again
            again = np.array([np.any((handed > a) & (handed < b)) for a, b in zip(last, now)], dtype=bool)
            turned = np.union1d(handed, now[~again])
            if not len(turned) or len(turned) > 20:
                continue
            unseen = _unseen_changes(seen[:, i], seen[:, j]) if len(turned) == 1 else ()
            out += [{"cols": (i, j), "span": (a, b), "keep": keep, "swap": swap, "steps": True}
                    for a, b in spans_between(turned, F, unseen) if b - a + 1 >= MIN_RUN]
    return out


END_GAP = 2
"""At most this many frames apart are the two posed frames a turn across a span's end is read between
(:func:`exchange_turns_over`): a segment turning 6 deg a frame (a shank in swing at 100 Hz) turns 90 deg over 15
frames, and a turn read across a gap that long is motion, not a flip."""


def _end_turns(labelled: np.ndarray, exchanged: np.ndarray, local: np.ndarray, a: int, b: int) -> list:
    """For each end of the span a..b both labellings can be read across: (the segment's turn as labelled, its turn
    exchanged), deg, its points (F, m, 3) posed with the body-fixed `local` (m, 3) and both turns read between the
    same two frames: the one nearest the end inside the span and the one nearest it outside that both labellings
    pose, at most :data:`END_GAP` frames apart. An end at the trial's edge, or without such frames, gives nothing."""
    F, out = len(labelled), []
    for inside, outside in ((range(a, min(b, a + END_GAP - 1) + 1), range(a - 1, max(a - 1 - END_GAP, -1), -1)),
                            (range(b, max(a, b - END_GAP + 1) - 1, -1), range(b + 1, min(b + 1 + END_GAP, F)))):
        rows = list(inside) + list(outside)
        if not len(outside):
            continue
        poses = [segment_poses(x[rows], local) for x in (labelled, exchanged)]
        both = poses[0].valid & poses[1].valid
        p = next((k for k in range(len(inside)) if both[k]), None)
        q = next((k for k in range(len(inside), len(rows)) if both[k]), None)
        if p is not None and q is not None and abs(rows[q] - rows[p]) <= END_GAP:
            out.append(tuple(float(_angle_deg(ps.R[p], ps.R[q])) for ps in poses))
    return out


def exchange_turns_over(data: np.ndarray, chain, cols: tuple, span: tuple, local: np.ndarray | None = None) -> bool:
    """Whether exchanging the labels of markers `cols` over rows `span` turns a segment they sit on over: at every end
    of the span that can be read (:func:`_end_turns`, at least one), by more than :data:`FLIP_DEG` and by more than as
    labelled. The exchanged markers are then posed only by turning the segment over (their shape is its mirror image,
    or nearly), and the exchange is no swap. `local` (M, 3): the markers' body-fixed positions (each segment's
    :func:`~identcheck.geometry.poses.reference_shape` by default). Segments whose markers do not pose them (fewer than
    three, or all near one line: their roll is noise, :func:`~identcheck.geometry.poses.poses_segment`), or that
    cannot be posed near an end, say nothing.

    Why: the distances within a segment cannot tell it from its mirror image. Three thigh markers on the real walking2
    trial whose distances were off by 7 mm RMS for 4 frames fitted their distances better with two of them
    exchanged; the exchange turned the thigh by 179 deg at both ends, and each such candidate, refitted in every round
    of ``diagnose``, scored −7 million. A true exchange undoes the turns its swap made (on the held-out swaps of
    draws 67-69: at most 40 deg after, from up to 180 as labelled), and a true swap proposed with its span a frame
    off turns its segment over at one end only."""
    (i, j), (a, b) = cols, span
    for seg in {chain.marker_seg[i], chain.marker_seg[j]}:
        idx = list(chain.seg_markers[seg])
        labelled = data[:, idx]
        if not poses_segment(labelled):                 # fewer than three markers, or a roll that is noise
            continue
        exchanged = data[:, idx].copy()
        for src, dst in ((i, j), (j, i)):               # each exchanged marker of the segment takes the other's samples
            if src in idx:
                exchanged[a:b + 1, idx.index(src)] = data[a:b + 1, dst]
        try:
            shape = reference_shape(labelled) if local is None else local[idx]
            ends = _end_turns(labelled, exchanged, shape, a, b)
        except ValueError:                              # no frame shows them all, or a shape no pose can be fitted to
            continue
        if ends and all(x > FLIP_DEG and x > lab for lab, x in ends):
            return True
    return False


def fits_exchanged(found: dict) -> bool:
    """Whether a swap :func:`detect` found fits exchanged within its margin over most of its span (median frame):
    a real swap does; an artefact on one marker (a bad gap edge) or an echo of another swap can merely fit better."""
    a, b = found["span"]
    return bool(np.nanmedian(found["swap"][a:b + 1]) <= found["clear"])


MAX_SWAPS = 5            # swaps looked for, strongest first, each exchanged back before the next search


def screen(model, trial) -> tuple:
    """(trial with each detected swap span set missing for its two markers, list of warnings: dicts with
    ``kind`` = "label_swap", ``markers``, ``frames`` (first, last; 0-based rows), ``file_frames`` (the same
    in the file's own numbering, as the capture software shows them) and ``message``)."""

    chain = Skeleton.from_model(model)
    present = set(trial.labels)
    if any(m not in present for m in chain.labels):
        return trial, []                 # missing markers are reported by the fit itself
    data = trial.select(chain.labels).as_array()
    segments = {s: model.segments[s].markers for s in model.segments}
    try:
        noise = noise_floor(data, chain.labels, segments)
    except InputError:
        return trial, []                 # no two markers share a segment: distances cannot tell
    # the scale is the distances' whole-trial scatter, which includes skin motion: a swap moves a distance
    # by tens of mm, skin motion by a few, and frame-to-frame noise alone (often 0.02 mm in filtered
    # recordings) would let a few mm of skin motion pass for a swap
    sigma = max(noise.sigma_mm, noise.sigma_scatter_mm)
    if not sigma > 0:
        return trial, []
    n_obs = int(np.all(np.isfinite(data), axis=2).sum())
    xyz = trial.as_array().copy()
    col = {m: i for i, m in enumerate(trial.labels)}
    warnings = []

    def leave_out(i: int, j: int, a: int, b: int, why: str) -> None:
        """Rows a..b left out for markers i and j (chain columns), with the warning saying why."""
        mi, mj = chain.labels[i], chain.labels[j]
        xyz[a:b + 1, [col[mi], col[mj]]] = np.nan
        fa, fb = trial.frame_number(a), trial.frame_number(b)
        warnings.append({"kind": "label_swap", "markers": [mi, mj], "frames": [int(a), int(b)],
                         "file_frames": [fa, fb],
                         "message": f"{trial.source}: markers {mi} and {mj} look swapped in frames {fa}-{fb} of the "
                                    f"file (rows {a}-{b}; {why}); those frames are left out for these two markers. "
                                    f"Which labelling is right, only a reference (static) trial can tell: check the "
                                    f"labels."})

    for _ in range(MAX_SWAPS):
        found = [d for d in detect(data, chain, sigma, n_obs) if fits_exchanged(d)]
        if not found:
            break
        (i, j), (a, b) = found[0]["cols"], found[0]["span"]     # the strongest; others may be its echoes
        data[a:b + 1, [i, j]] = data[a:b + 1, [j, i]]              # exchanged back, to look for more
        leave_out(i, j, a, b, "there, their distances to the other markers of their segments fit clearly better "
                              "exchanged than as labelled in the rest of the trial")
    for d in flips(data, chain):               # exchanges the distances cannot see: the segment's pose flips
        (i, j), (a, b) = d["cols"], d["span"]
        if not any({chain.labels[i], chain.labels[j]} <= set(w["markers"]) for w in warnings):
            leave_out(i, j, a, b, f"their segment turns by more than {FLIP_DEG:g} deg from one frame to the next at "
                                  "both ends of that span, and no longer does with the two exchanged; their distances "
                                  "to the rest of the segment are too alike to show it")
    for d in exchanges(data, chain):           # two markers alone on a segment, or a swap read across a gap
        (i, j), (a, b) = d["cols"], d["span"]
        if not any({chain.labels[i], chain.labels[j]} <= set(w["markers"]) for w in warnings):
            leave_out(i, j, a, b, "where their labels change over, each one's trajectory goes on from where the "
                                  "other's was last seen")
    if not warnings:
        return trial, []
    return trial.replace(xyz=xyz), warnings
