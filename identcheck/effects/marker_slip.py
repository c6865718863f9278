"""``marker_slip``: a marker shifts on its segment at one instant and stays there.

Detector: each marker's residual in its own segment's frame is scanned for the single change in mean
that explains most of its variance (a CUSUM split). A slip may also take a moment (tape giving way, a marker
sliding over skin for a fraction of a second): linear ramps of a few set durations centred on that frame are tried
too (:func:`best_ramp`), the one explaining most kept when it earns its extra parameter. Each marker's step so found
is then scored by what a refit with it would gain to first order (:func:`refit_gain`, the score test of the step's
three displacement fields), and the markers are ranked by that: a segment's pose takes up part of one marker's step
and spreads the rest over its mates. Augmentation: a step (or
ramp) in the marker's position on its segment from that frame on (3 parameters, plus the frame, plus the ramp's
duration); ``where`` gives the first moved ``frame`` and, for a ramp, ``frames`` [first moved, first fully slipped].
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.model import Terms
from identcheck.bundle.hypothesis import segment_residuals
from identcheck.bundle.score_test import quadratic_form, stacked
from identcheck.effects.base import Effect, Proposal
from identcheck.effects.injection import Change, cannot, marker_column, draw_frame, pick, rotations, unit_vectors

MIN_SIDE = 5     # frames on each side of a step
RAMP_S = (0.03, 0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0, 1.5)
"""The durations (s) of the ramps tried about a step's frame: from a few frames to a slow creep."""


def best_step(resid: np.ndarray) -> tuple[int, float]:
    """(frame, explained sum of squares) of the best single mean shift of `resid` (F, 3), NaN rows skipped."""
    ok = np.flatnonzero(np.all(np.isfinite(resid), axis=1))
    n = len(ok)
    if n < 2 * MIN_SIDE:
        return -1, 0.0
    e = resid[ok]
    S = np.cumsum(e, axis=0)
    k = np.arange(1, n)
    left = S[:-1] / k[:, None]
    right = (S[-1] - S[:-1]) / (n - k)[:, None]
    stat = np.sum((left - right) ** 2, axis=1) * k * (n - k) / n
    stat[: MIN_SIDE - 1] = 0
    stat[n - MIN_SIDE:] = 0
    i = int(np.argmax(stat))
    return int(ok[i + 1]), float(stat[i])


def ramp(n_frames: int, onset: int, length: int) -> np.ndarray:
    """(F, 1): 0 before `onset`, rising linearly to 1 over `length` frames (a step for a length of 1), 1 after."""
    t = np.arange(n_frames, dtype=float)
    return np.clip((t - onset + 1.0) / max(length, 1), 0.0, 1.0)[:, None]


def explained_by(resid: np.ndarray, shape: np.ndarray) -> float:
    """The sum of squares of `resid` (F, 3) that `shape` (F, 1) times a free 3-vector, plus a constant, explains
    over the finite rows."""
    ok = np.all(np.isfinite(resid), axis=1)
    b = shape[ok, 0] - shape[ok, 0].mean()
    bb = float(b @ b)
    if bb <= 0.0:
        return 0.0
    r = resid[ok] - resid[ok].mean(axis=0)
    return float(np.sum((b @ r) ** 2) / bb)


def best_ramp(resid: np.ndarray, frame: int, rate_hz: float) -> tuple[int, int, float]:
    """(first moved frame, length in frames, explained sum of squares) of the best of a step at `frame` and the
    ramps of :data:`RAMP_S` centred on it (a change in mean found by :func:`best_step` sits mid-way up a ramp)."""
    n = len(resid)
    best = (frame, 1, explained_by(resid, ramp(n, frame, 1)))
    for seconds in RAMP_S:
        length = int(round(seconds * rate_hz))
        onset = frame - length // 2
        if length < 2 or onset < MIN_SIDE or onset + length > n - MIN_SIDE:
            continue
        found = explained_by(resid, ramp(n, onset, length))
        if found > best[2]:
            best = (onset, length, found)
    return best


class MarkerSlip(Effect):
    name = "marker_slip"
    max_proposals = 2

    def inject(self, sim, rng) -> Change:
        """One marker jumps on its segment at frame k (in [F/4, 3F/4]) by 6-15 mm and stays."""
        model, n = sim.model, sim.clean.n_frames
        if not model.markers:
            raise cannot(self.name, "the model has no marker")
        marker = pick(rng, model.markers)
        seg = model.marker_segment(marker)
        frame = draw_frame(rng, 0.25 * n, 0.75 * n, n)
        size = rng.uniform(6.0, 15.0)
        step = size * unit_vectors(rng, 1)[0]
        clean = sim.clean.as_array()
        clean[frame:, marker_column(sim, marker)] += rotations(sim, seg)[frame:] @ step
        return Change(where={"markers": [marker], "segment": seg, "frame": frame},
                       params={"step_mm": size, "step_local": step}, clean=clean)

    def propose(self, ctx, hyp) -> list:
        """Each marker's best step (or ramp) in its segment's frame, its strength what a refit with it gains to first
        order (:func:`refit_gain`)."""
        seg_res = segment_residuals(hyp)
        ch = hyp.chain
        found = []
        for col in range(ch.n_markers):
            frame, ss = best_step(seg_res[:, col])
            if frame < 0:
                continue
            onset, length, explained = best_ramp(seg_res[:, col], frame, ctx.rate_hz)
            if length > 1 and ctx.bic_gain(explained, 5) > ctx.bic_gain(ss, 4):   # the ramp's length: one more
                frame = onset
            else:
                length = 1
            found.append((col, frame, length, ramp(len(seg_res), frame, length)))
        out = []
        for (col, frame, length, basis), gain in zip(found, refit_gain(ctx, hyp, found)):
            if gain > 0:
                where = {"markers": [ch.labels[col]], "segment": ch.marker_seg[col], "frame": frame}
                if length > 1:
                    where["frames"] = [frame, frame + length - 1]
                out.append(Proposal(self.name, where, gain, {"col": col, "basis": basis, "length": length}))
        return sorted(out, key=lambda p: -p.strength)

    def apply(self, ctx, hyp, proposal):
        term = (proposal.payload["col"], proposal.payload["basis"])
        ramped = int(proposal.payload.get("length", 1) > 1)
        return hyp.refit(terms=hyp.terms + Terms(markers=[term]), extra_params=1 + ramped, effect=proposal)

    def evidence(self, ctx, before, after, proposal) -> dict:
        col = proposal.payload["col"]
        return {"x": np.arange(len(before.data)), "x_label": "frame",
                "y": segment_residuals(before)[:, col], "y_after": segment_residuals(after)[:, col],
                "y_label": f"{proposal.where['markers'][0]} residual on {proposal.where['segment']} (mm, x/y/z)",
                "mark": [proposal.where["frame"]], "kind": "series3"}


def step_fields(hyp, col: int, basis: np.ndarray) -> np.ndarray:
    """The displacements (F, M, 3, 3) of marker `col` moved by `basis` (F, 1) times a unit step along each axis of its
    segment's frame (the last axis), as the fit poses the segment: a slip's three fields."""
    R = hyp.fit.seg_R[hyp.chain.marker_seg[col]]                                   # (F, 3, 3), segment to world
    out = np.zeros(hyp.data.shape + (3,))
    out[:, col] = basis[:, :, None] * R
    return out


def refit_gain(ctx, hyp, found: list) -> list:
    """For each step or ramp in `found` ((column, first moved frame, length, basis)), the criterion's gain of a refit
    with it, to first order: the score statistic of its three fields (:func:`step_fields`) on the criterion's scale,
    net of its parameters (4, a ramp 5). The scale is :meth:`~identcheck.bundle.hypothesis.Context.kept_share` of the
    fitted step less its mean over the marker's seen frames, which the marker's own place on its segment takes up
    (the whole step's share read as little as 0.35 of the refit's gain at φ 0.95 over 300 frames). The markers'
    fields are projected together in stacks (:func:`~identcheck.bundle.score_test.stacked`, each marker's three in
    one), and only each marker's own 3 × 3 block of their Gram matrix is formed.

    Why not the marker's own residual: the rigid fit poses the segment through the slipped marker too, so part of
    its step is taken up and the rest shows on its mates. A pelvis of three markers whose LASI slipped 4.5 mm
    (AR(1) noise, held-out draw 75, trial 111) read its best split on RASI (78 against 51) and LASI was not among
    the two places fitted; the refit with LASI's step at its split's frame gains 118, RASI's 39."""
    proj = hyp.projection
    w = hyp.weights
    wr = (np.where((w > 0)[..., None], np.nan_to_num(hyp.residuals()), 0.0) * w[..., None]).reshape(-1)
    out = []
    markers = iter(found)
    for V in stacked(step_fields(hyp, col, basis) for col, _, _, basis in found):     # each marker's three together
        count = V.shape[-1] // 3
        V0, Z, reduced = proj.pieces_many(V, owned=True)
        for j in range(count):
            col, _, length, basis = next(markers)
            mine = slice(3 * j, 3 * j + 3)
            n = V0[..., mine].reshape(-1, 3).T @ wr
            G = proj.gram(V0[..., mine], Z[..., mine], reduced[:, mine])
            stat = quadratic_form(n, G)
            seen = w[:, col] > 0
            centred = np.where(seen[:, None], basis - basis[seen].mean(), 0.0)
            step = np.linalg.pinv(G, rcond=1e-10, hermitian=True) @ n
            field = step_fields(hyp, col, centred) @ step
            out.append(ctx.bic_gain(stat * ctx.kept_share(field, w), 5 if length > 1 else 4))
    return out
