"""``time_offset``: one segment's markers lag the others by a constant delay.

Detector: a lag τ leaves residuals ≈ −τ·velocity on that segment's markers; the least-squares τ and
the variance it explains rank the segments. Augmentation: the segment's trajectories are shifted back
by τ (cubic spline through its visible samples), τ refined by Gauss-Newton with the velocity as the
derivative, and the model refitted (one parameter).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.interpolate import CubicSpline

from identcheck.bundle.chain import Terms
from identcheck.effects.base import Effect, Proposal
from identcheck.effects.injection import Change, cannot, marker_column, pick

NEWTON_STEPS = 3
MIN_DELAY_FRAMES = 0.2   # delays below a fifth of a frame are not worth a refit
TAU_TOL_S = 5e-5


def shifted(data: np.ndarray, rate_hz: float, tau_s: float, derivative: int = 0,
            extrapolate: bool = False) -> np.ndarray:
    """Each marker's trajectory (F, m, 3) evaluated at t + τ (or its time derivative), through its
    visible samples (a cubic spline); occluded samples stay NaN, and so do samples whose t + τ falls
    outside the marker's visible time span unless `extrapolate` (the injector delays a whole clean
    trajectory; the detector undoes a delay on measured data and must not invent samples)."""
    F = data.shape[0]
    t = np.arange(F) / rate_hz
    out = np.full_like(data, np.nan)
    for k in range(data.shape[1]):
        ok = np.all(np.isfinite(data[:, k]), axis=1)
        if ok.sum() < (2 if extrapolate else 4):
            continue
        spline = CubicSpline(t[ok], data[ok, k], axis=0)
        tt = t[ok] + tau_s
        inside = np.ones(len(tt), dtype=bool) if extrapolate else (tt >= t[ok][0]) & (tt <= t[ok][-1])
        rows = np.flatnonzero(ok)[inside]
        out[rows, k] = spline(tt[inside], derivative)
    return out


class TimeOffset(Effect):
    name = "time_offset"
    max_proposals = 3

    def inject(self, sim, rng) -> Change:
        """One segment's markers lag by 20-50 ms: x(t) becomes x(t - tau) (cubic spline)."""
        model = sim.model
        options = [s for s in model.segments if model.segments[s].markers]
        if not options:
            raise cannot(self.name, "the model has no marker")
        if sim.clean.n_frames < 2:
            raise cannot(self.name, "a delay needs at least 2 frames")
        seg = pick(rng, options)
        delay_ms = rng.uniform(20.0, 50.0)
        clean = sim.clean.as_array()
        cols = [marker_column(sim, m) for m in model.segments[seg].markers]
        clean[:, cols] = shifted(clean[:, cols], sim.clean.rate_hz, -delay_ms / 1000.0, extrapolate=True)
        return Change(where={"segment": seg, "delay_ms": delay_ms},
                       params={"delay_frames": delay_ms / 1000.0 * sim.clean.rate_hz}, clean=clean)

    def propose(self, ctx, hyp) -> list:
        ch = hyp.chain
        res = np.where((hyp.weights > 0)[..., None], hyp.residuals(), np.nan)
        out = []
        for seg in ch.segments:
            idx = ch.seg_markers[seg]
            v = shifted(hyp.data[:, idx], ctx.rate_hz, 0.0, derivative=1)
            r = res[:, idx]
            ok = np.isfinite(v) & np.isfinite(r)
            vv = float(np.sum(np.where(ok, v * v, 0)))
            rv = float(np.sum(np.where(ok, r * v, 0)))
            if vv <= 0:
                continue
            tau = -rv / vv
            gain = ctx.bic_gain(rv * rv / vv, 1)
            if gain <= 0 or abs(tau) * ctx.rate_hz < MIN_DELAY_FRAMES:   # explains nothing worth a refit
                continue
            out.append(Proposal(self.name, {"segment": seg, "delay_ms": 1000 * tau}, float(gain),
                                {"segment": seg, "tau": tau}))
        return sorted(out, key=lambda p: -p.strength)

    def apply(self, ctx, hyp, proposal):
        seg = proposal.payload["segment"]
        idx = hyp.chain.seg_markers[seg]
        tau = proposal.payload["tau"]
        base = hyp.data
        current = hyp
        for _ in range(NEWTON_STEPS):
            data = base.copy()
            data[:, idx] = shifted(base[:, idx], ctx.rate_hz, tau)
            vel = shifted(base[:, idx], ctx.rate_hz, tau, derivative=1)
            term = (idx, np.nan_to_num(vel))           # corrected(t) + dτ·v ≈ measured at t + τ + dτ
            stepped = current.refit(data=data, terms=hyp.terms + Terms(world=[term]), max_iter=3)
            dtau = -float(stepped.fit.state.term_params[-1][0])
            tau += dtau
            current = replace(stepped, terms=hyp.terms)
            current.fit.state.term_params = current.fit.state.term_params[:-1]
            if abs(dtau) < TAU_TOL_S:
                break
        data = base.copy()
        data[:, idx] = shifted(base[:, idx], ctx.rate_hz, tau)
        lost = np.isfinite(base).all(axis=2) & ~np.isfinite(data).all(axis=2)
        new = current.refit(data=data, weights=np.where(lost, 0.0, hyp.weights), max_iter=8)
        new.extra_params = hyp.extra_params + 1 + 3 * int(lost.sum())     # a set-aside sample costs 3
        new.effects = hyp.effects + [proposal]
        proposal.where["delay_ms"] = round(1000 * tau, 2)
        proposal.payload["tau"] = tau
        return new

    def evidence(self, ctx, before, after, proposal) -> dict:
        seg = proposal.payload["segment"]
        idx = before.chain.seg_markers[seg]
        v = shifted(before.data[:, idx], ctx.rate_hz, 0.0, derivative=1)
        r = np.where((before.weights > 0)[:, idx, None], before.residuals()[:, idx], np.nan)
        return {"x": np.nansum(v * r, axis=(1, 2)) / np.maximum(np.nansum(v * v, axis=(1, 2)), 1e-9) * -1000,
                "x_label": "frame-wise delay estimate (ms)", "y": np.linalg.norm(np.nanmean(v, axis=1), axis=1),
                "y_label": f"{seg} speed (mm/s)", "kind": "scatter"}
