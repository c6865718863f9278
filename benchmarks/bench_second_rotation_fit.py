"""Fits of a knee that turns like a ball (a hinge with two second rotations), with the derivative of each rotation's
profile taken through the left Jacobian of the whole second rotation (the package) and as a turn about the
profile's own axis (what it was before 2026-12-05), side by side on the same noise draws.

Each draw: the bundled diagnose leg simulated, its knee given two smooth second rotations of `--peak-deg` about
axes across the hinge, noise of `--noise-mm` added, and the model refitted from the truth (as the bootstrap's draws
are), stopping as they do (a drop below 1e-3 σ² per iteration) or at 100 iterations. Prints a table and writes
``results.json["second_rotation_fit"]``: per derivative, the iterations, whether the fit converged, CPU seconds and
the final cost over the other derivative's.

    python benchmarks/bench_second_rotation_fit.py [--draws 8] [--frames 1500]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import results_io  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _truth(frames: int, peak_deg: float, seed: int):
    """The leg's chain, terms and true state: the rigid fit of a clean simulation, its knee's point moved near its
    markers, and two smooth second rotations about axes across the hinge."""
    from identcheck.bundle.chain import fit_chain, initial_state
    from identcheck.bundle.hypothesis import time_basis
    from identcheck.bundle.model import Terms
    from identcheck.effects.extra_dof import pivot_at_markers
    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate
    from identcheck.skeleton import Skeleton

    model = Model.from_toml(ROOT / "examples" / "diagnose_leg.toml")
    sim = simulate(model, n_frames=frames, seed=seed)
    chain = Skeleton.from_model(model)
    data = sim.clean.as_array()
    state = pivot_at_markers(chain, fit_chain(chain, data, initial_state(chain, data), max_iter=60).state, "knee")
    basis = time_basis(frames, sim.clean.rate_hz)
    rng = np.random.default_rng(seed)
    terms = Terms(rotations=[("knee", basis, 0.4), ("knee", basis, 0.4 + np.pi / 2)])
    params = []
    for _ in range(2):
        coef = rng.normal(size=(basis.shape[1], 1))
        coef *= np.deg2rad(peak_deg) / np.abs(basis @ coef).max()
        params.append(np.vstack([coef, [[0.0]]]))
    state.term_params = params
    return chain, terms, state


def _fit(chain, terms, state, y, sigma: float, derivative: str) -> dict:
    """One refit from the truth with the chosen derivative of the profiles."""
    import identcheck.bundle.jacobian as jacobian
    from identcheck.bundle.chain import REL_TOL, fit_chain
    from identcheck.bundle.model import forward
    from identcheck.bundle.profile import STEP_CHI2
    from identcheck.geometry.rotations import left_jacobian_times

    jacobian.left_jacobian_times = left_jacobian_times if derivative == "left Jacobian" else (
        lambda v, u: np.broadcast_to(u, np.shape(v)).copy())
    try:
        rss0 = float(np.sum((y - forward(chain, terms, state)[3]) ** 2))
        tol = max(REL_TOL, STEP_CHI2 * sigma ** 2 / max(rss0, 1e-300))
        t0 = time.process_time()
        f = fit_chain(chain, y, state, terms=terms, max_iter=100, tol=tol)
        return {"iterations": f.iterations, "converged": bool(f.converged), "cpu_s": time.process_time() - t0,
                "rss": float(f.rss)}
    finally:
        jacobian.left_jacobian_times = left_jacobian_times


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--frames", type=int, default=1500)
    ap.add_argument("--peak-deg", type=float, default=20.0)
    ap.add_argument("--noise-mm", type=float, default=0.5)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    a = ap.parse_args(argv)
    chain, terms, truth = _truth(a.frames, a.peak_deg, a.seed)
    from identcheck.bundle.model import forward

    clean = forward(chain, terms, truth)[3]
    rows = []
    for k in range(a.draws):
        y = clean + np.random.default_rng([a.seed, k]).normal(scale=a.noise_mm, size=clean.shape)
        row = {"draw": k}
        for derivative in ("left Jacobian", "own axis"):
            row[derivative] = _fit(chain, terms, truth, y, a.noise_mm, derivative)
        row["rss_own_minus_left"] = row["own axis"]["rss"] - row["left Jacobian"]["rss"]
        rows.append(row)
        print(f"draw {k}: iterations {row['left Jacobian']['iterations']:3d} vs {row['own axis']['iterations']:3d}, "
              f"CPU {row['left Jacobian']['cpu_s']:.2f} vs {row['own axis']['cpu_s']:.2f} s, final cost "
              f"{row['rss_own_minus_left']:+.3f} mm² higher with the own-axis derivative", flush=True)
    summary = {}
    for derivative in ("left Jacobian", "own axis"):
        its = [r[derivative]["iterations"] for r in rows]
        summary[derivative] = {"median_iterations": float(np.median(its)), "max_iterations": int(max(its)),
                               "converged": int(sum(r[derivative]["converged"] for r in rows)),
                               "cpu_s": float(sum(r[derivative]["cpu_s"] for r in rows))}
    print(f"\n{'derivative':16s} {'median it':>9s} {'max it':>7s} {'converged':>10s} {'CPU s':>7s}")
    for derivative, s in summary.items():
        print(f"{derivative:16s} {s['median_iterations']:9.1f} {s['max_iterations']:7d} "
              f"{s['converged']:>5d}/{len(rows):<4d} {s['cpu_s']:7.1f}")
    results_io.write_json(a.out, "second_rotation_fit", {
        "machine": results_io.machine_info(), "draws": a.draws, "frames": a.frames, "peak_deg": a.peak_deg,
        "noise_mm": a.noise_mm, "seed": a.seed, "rows": rows, "summary": summary})
    return 0


if __name__ == "__main__":
    sys.exit(main())
