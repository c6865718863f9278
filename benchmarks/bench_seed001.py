"""Benchmark of seed 001's joint-centre estimator: is its predicted covariance calibrated?

Monte-Carlo trials with a known centre (``identcheck.simulate.rigid``), fitted by
:func:`identcheck.estimate.seed001.fit_centre` three ways:

* ``this``: 6 unknowns (centre in each body frame), noise-corrected Gauss–Markov (default);
* ``no-bc``: the same without the O(σ²) corrections (eqs. 22–23 as printed, 6 unknowns);
* ``paper``: seed 001 as printed: one point in body frames that coincide at frame 0 (eq. 9),
  eqs. 12–23, no corrections.

For each fit the validation index of eq. (16), ``v = sqrt(e/3)``, is taken against the *true*
centre, after moving the fit into the true parent frame by the least-squares rigid motion of
its marker coordinates (``CentreFit.in_frame``). A calibrated covariance gives ``E[v²] = 1``,
``E[v] = 0.921`` and ``P(e > χ²₃,0.95) = 5%``.

Sections:

1. **Calibration** over scenarios: the paper's rig (two 3-marker clusters ~0.5 m either side of
   the ball, 60 Hz, σ = 1 mm per coordinate, i.e. √tr Wy = 1.7 mm as in section 8), with and
   without gaps; the hip of ``examples/hip_s22.toml`` at 1 and 2 mm; the rig with serially
   correlated (AR(1)) noise, ``serial="white"`` vs ``"ar1"``. Noise is estimated from the trial
   (inter-marker distance scatter, section 8).
2. **Table 1**: uncertainty ``sqrt(tr Wc)`` and validation index vs number of frames (the first
   Nt frames of 20 s rig trials), against the truth and, as the paper did, against the method's
   own 1200-frame estimate. The paper's printed values alongside.
3. **Excitation sweep**: rig clusters, relative rotation about a main axis plus a second axis
   scaled by k ∈ [0, 0.4]; RMS v per bin of ``information_fraction`` (the basis of ``INFO_OK``).
4. **eq. (5) convergence**: iterations of ``refine_local`` until the body-fixed coordinates stop
   changing at 15 significant digits.

Results go to ``benchmarks/results.json`` under ``"seed001"`` (other keys kept) and a figure to
``benchmarks/seed001_calibration.png``.

Run from the repository root::

    PYTHONPATH=. python3 benchmarks/bench_seed001.py            # about 1.5 min on 2 cores
    PYTHONPATH=. python3 benchmarks/bench_seed001.py --quick    # seconds; writes nothing
"""
from __future__ import annotations

import argparse
import datetime
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow running without PYTHONPATH
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_io import machine_info, write_json  # noqa: E402
from identcheck.errors import DegenerateError  # noqa: E402
from identcheck.geometry.poses import refine_local  # noqa: E402
from identcheck.estimate.seed001 import (EXPECTED_MEAN_V, INFO_FAIL, INFO_OK, fit_centre,  # noqa: E402
                                    marker_noise, validation_index)
from identcheck.io.model import Model  # noqa: E402
from identcheck.simulate.rigid import simulate  # noqa: E402

KEY = "seed001"
FIGURE = ROOT / "benchmarks" / "seed001_calibration.png"
RATE_HZ = 60.0
RIG = Model.from_dict({
    "units": "mm",
    "segments": {
        "link_a": {"markers": ["A1", "A2", "A3"],
                   "positions": {"A1": [60.0, 0.0, 450.0], "A2": [-50.0, 70.0, 520.0], "A3": [-20.0, -80.0, 560.0]}},
        "link_b": {"markers": ["B1", "B2", "B3"],
                   "positions": {"B1": [50.0, 30.0, -470.0], "B2": [-60.0, -40.0, -520.0], "B3": [20.0, 90.0, -560.0]}}},
    "joints": {"ball": {"type": "spherical", "parent": "link_a", "child": "link_b",
                        "centre_parent": [0.0, 0.0, 0.0]}}}, source="seed 001 rig")
"""Seed 001's test rig (section 8): 3 markers per segment 100-200 mm apart, the two sets about
1 m apart with the joint halfway."""
HIP = Model.from_toml(ROOT / "examples" / "hip_s22.toml")
METHODS = {"this": {}, "no-bc": {"bias_correction": False},
           "paper": {"method": "paper", "bias_correction": False}}
SCENARIOS = {
    # name: (model, joint, n_frames, rate, noise_mm, rom_deg, n_axes, occlusion, ar1_rho)
    "rig 1200 fr": (RIG, "ball", 1200, RATE_HZ, 1.0, 60.0, 2, 0.0, 0.0),
    "rig 300 fr, 20% gaps": (RIG, "ball", 300, RATE_HZ, 1.0, 60.0, 2, 0.2, 0.0),
    "hip 600 fr": (HIP, "hip_r", 600, 100.0, 1.0, 40.0, 3, 0.0, 0.0),
    "hip 1200 fr, 2 mm": (HIP, "hip_r", 1200, 100.0, 2.0, 40.0, 3, 0.0, 0.0),
    "rig 600 fr, AR(1) 0.7": (RIG, "ball", 600, RATE_HZ, 1.0, 60.0, 2, 0.0, 0.7),
}
TABLE1_NT = (4, 8, 16, 32, 75, 150, 300, 600, 1200)
PAPER_TABLE1 = {4: (1872.02, 0.46), 8: (96.04, 2.62), 16: (76.60, 3.18), 32: (35.93, 2.97),
                75: (3.04, 1.82), 150: (1.10, 3.05), 300: (0.50, 2.99), 600: (0.30, 1.38), 1200: (0.20, None)}
"""Seed 001, Table 1: Nt → (sqrt(tr Wc) mm, validation index against the 1200-frame estimate)."""
CHI2_95 = float(chi2.ppf(0.95, 3))


# ---------------------------------------------------------------------- one trial
def segments(sim, joint):
    j = sim.model.joints[joint]
    p = sim.trial.select(sim.model.segments[j.parent].markers).xyz
    c = sim.trial.select(sim.model.segments[j.child].markers).xyz
    local = np.array(list(sim.truth.segments[j.parent].marker_local.values()))
    return p, c, sim.truth.joints[joint].centre_parent, local


def fit_stats(fit, centre, local) -> dict:
    """v, e and the true error of one fit (NaN v when the centre is not determined)."""
    if not np.isfinite(fit.uncertainty_mm):
        return {"v": np.nan, "e": np.nan, "err": np.nan, "unc": np.inf, "trace": np.inf,
                "ok": fit.excitation_ok, "frac": fit.information_fraction}
    c, W = fit.in_frame(local)
    v = validation_index(c, centre, W)
    return {"v": v, "e": 3 * v**2, "err": float(np.linalg.norm(c - centre)), "unc": fit.uncertainty_mm,
            "trace": fit.rms_uncertainty_mm, "ok": fit.excitation_ok, "frac": fit.information_fraction}


def calibration_trial(args) -> dict:
    name, seed = args
    model, joint, n, rate, noise, rom, n_axes, occ, rho = SCENARIOS[name]
    sim = simulate(model, n_frames=n, rate_hz=rate, noise_mm=0.0 if rho else noise, rom_deg=rom,
                   n_axes=n_axes, occlusion=occ, seed=seed)
    p, c, centre, local = segments(sim, joint)
    if rho:   # AR(1) noise with the same per-sample σ: seed 001's noise model broken on purpose
        rng = np.random.default_rng(10_000 + seed)
        e = lfilter([np.sqrt(1 - rho**2)], [1, -rho], rng.normal(0, noise, (n, p.shape[1] + c.shape[1], 3)), axis=0)
        p, c = p + e[:, :p.shape[1]], c + e[:, p.shape[1]:]
    methods = dict(METHODS)
    if rho:
        methods = {"this": {}, "this, ar1": {"serial": "ar1"}, "paper": METHODS["paper"]}
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for m, kw in methods.items():
            fit = fit_centre(p, c, **kw)
            out[m] = fit_stats(fit, centre, local)
            out[m]["noise"] = fit.noise_mm
            out[m]["rho"] = fit.residual_autocorr
    return out


def table1_trial(seed: int) -> dict:
    """First-Nt-frames fits of one 20 s rig trial; noise estimated once from all frames."""
    sim = simulate(RIG, n_frames=1200, rate_hz=RATE_HZ, noise_mm=1.0, rom_deg=60.0, n_axes=2, seed=seed)
    p, c, centre, local = segments(sim, "ball")
    noise = marker_noise(p, c).noise_mm
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for m in ("this", "paper"):
            fits = {}
            for nt in TABLE1_NT:
                try:
                    fits[nt] = fit_centre(p[:nt], c[:nt], noise_mm=noise, **METHODS[m])
                except DegenerateError:
                    fits[nt] = None
            ref = fits[1200]
            rows = {}
            for nt, fit in fits.items():
                if fit is None:
                    rows[nt] = {"v": np.nan, "trace": np.inf, "err": np.nan, "v_ref": np.nan}
                    continue
                s = fit_stats(fit, centre, local)
                if np.isfinite(fit.uncertainty_mm) and nt < 1200:
                    if m == "paper":   # as seed 001: same frame-0 world, compare directly
                        s["v_ref"] = validation_index(fit.centre_parent, ref.centre_parent, fit.covariance)
                    else:              # move into the 1200-frame fit's parent frame first
                        cc, W = fit.in_frame(ref.parent_local)
                        s["v_ref"] = validation_index(cc, ref.centre_parent, W)
                else:
                    s["v_ref"] = np.nan
                rows[nt] = s
            out[m] = rows
    return out


def sweep_trial(seed: int) -> dict:
    """Rig clusters, relative rotation about a main axis plus a second one scaled by k."""
    rng = np.random.default_rng(20_000 + seed)
    k = float(rng.uniform(0.0, 0.4))
    noise = float(rng.uniform(0.5, 1.5))
    n = int(rng.integers(100, 600))
    x0 = np.array(list(RIG.segments["link_a"].positions.values()))
    x1 = np.array(list(RIG.segments["link_b"].positions.values()))
    t = np.arange(n)[:, None] / RATE_HZ
    s = np.sin(2 * np.pi * rng.uniform(0.2, 1.0, 3) * t + rng.uniform(0, 2 * np.pi, 3))
    axes = Rotation.random(random_state=seed).as_matrix()
    omega = np.deg2rad(30) * (s[:, :1] * axes[:, 0] + k * s[:, 1:2] * axes[:, 1])
    R0 = Rotation.from_rotvec(np.deg2rad(10) * s[:, ::-1]).as_matrix()
    d0 = 100 * s + [0, 0, 1000]
    R1 = R0 @ Rotation.from_rotvec(omega).as_matrix()
    d1 = d0                                             # centre at both frames' origin
    y0 = np.einsum("fij,mj->fmi", R0, x0) + d0[:, None] + rng.normal(0, noise, (n, 3, 3))
    y1 = np.einsum("fij,mj->fmi", R1, x1) + d1[:, None] + rng.normal(0, noise, (n, 3, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fit = fit_centre(y0, y1, noise_mm=noise)
        except DegenerateError:
            return {"k": k, "frac": np.nan, "v": np.nan}
    # v with the covariance the fit would report if it trusted itself (finite even when flagged)
    c, W = fit.in_frame(x0)
    return {"k": k, "frac": fit.information_fraction, "v": validation_index(c, np.zeros(3), W),
            "ok": fit.excitation_ok, "finite": bool(np.isfinite(fit.uncertainty_mm))}


def refine_iterations(seed: int, noise: float) -> int:
    """Iterations of eq. (5) until no body-fixed coordinate changes by more than 1e-15 of the
    largest one (machine precision of a double, i.e. about 15 decimals)."""
    sim = simulate(RIG, n_frames=1200, rate_hz=RATE_HZ, noise_mm=noise, rom_deg=60.0, n_axes=2, seed=seed)
    p = segments(sim, "ball")[0]
    prev = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k in range(1, 12):
            local, _ = refine_local(p, n_iter=k, tol=0.0)
            if prev is not None and np.max(np.abs(local - prev)) <= 1e-15 * np.max(np.abs(local)) * 4:
                return k - 1
            prev = local
    return 99


# ---------------------------------------------------------------------- summaries
def summarise(rows: list[dict]) -> dict:
    v = np.array([r["v"] for r in rows], dtype=float)
    fin = np.isfinite(v)
    vf = v[fin]
    e = 3 * vf**2
    n = max(len(vf), 1)
    return {"n": int(len(v)), "n_determined": int(fin.sum()),
            "mean_v": float(vf.mean()) if len(vf) else None,
            "mean_v_se": float(vf.std(ddof=1) / np.sqrt(n)) if len(vf) > 1 else None,
            "rms_v": float(np.sqrt(np.mean(vf**2))) if len(vf) else None,
            "p_exceed_95": float(np.mean(e > CHI2_95)) if len(vf) else None,
            "median_uncertainty_mm": float(np.median([r["unc"] for r in rows])),
            "median_sqrt_tr_mm": float(np.median([r["trace"] for r in rows])),
            "rms_error_mm": float(np.sqrt(np.nanmean([r["err"] ** 2 for r in rows]))) if len(vf) else None,
            "excitation_ok": float(np.mean([r["ok"] for r in rows])),
            "noise_mm": float(np.mean([r["noise"] for r in rows])) if "noise" in rows[0] else None,
            "residual_autocorr": float(np.mean([r["rho"] for r in rows])) if "rho" in rows[0] else None}


def run(trials: int, t1_trials: int, sweep: int, workers: int) -> dict:
    t0 = time.perf_counter()
    jobs = [(name, seed) for name in SCENARIOS for seed in range(trials)]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        cal = list(pool.map(calibration_trial, jobs, chunksize=4))
        t_cal = time.perf_counter() - t0
        t1 = list(pool.map(table1_trial, range(t1_trials), chunksize=2))
        t_t1 = time.perf_counter() - t0 - t_cal
        sw = list(pool.map(sweep_trial, range(sweep), chunksize=8))
        it1 = list(pool.map(refine_iterations, range(10), [1.0] * 10))
        it3 = list(pool.map(refine_iterations, range(10), [3.0] * 10))
    calibration = {}
    for name in SCENARIOS:
        rows = [r for (nm, _), r in zip(jobs, cal) if nm == name]
        calibration[name] = {m: summarise([r[m] for r in rows]) for m in rows[0]}
    table1 = []
    for nt in TABLE1_NT:
        row = {"n_frames": nt, "paper_sqrt_tr_mm": PAPER_TABLE1[nt][0], "paper_v": PAPER_TABLE1[nt][1]}
        for m in ("this", "paper"):
            rs = [t[m][nt] for t in t1]
            v = np.array([r["v"] for r in rs], float)
            vr = np.array([r["v_ref"] for r in rs], float)
            tr = np.array([r["trace"] for r in rs], float)
            err = np.array([r["err"] for r in rs], float)
            q25, q50, q75 = np.quantile(tr, [0.25, 0.5, 0.75], method="lower")   # inf = not determined
            row[m] = {"median_sqrt_tr_mm": float(q50), "q25_sqrt_tr_mm": float(q25), "q75_sqrt_tr_mm": float(q75),
                      "rms_error_mm": float(np.sqrt(np.nanmean(err**2))) if np.isfinite(err).any() else None,
                      "n_determined": int(np.isfinite(v).sum()),
                      "mean_v": float(np.nanmean(v)) if np.isfinite(v).any() else None,
                      "rms_v": float(np.sqrt(np.nanmean(v**2))) if np.isfinite(v).any() else None,
                      "mean_v_vs_1200": float(np.nanmean(vr)) if np.isfinite(vr).any() else None}
        table1.append(row)
    bins = [(-np.inf, 0.0), (0.0, 0.25), (0.25, 0.4), (0.4, 0.55), (0.55, 0.7), (0.7, 0.85), (0.85, 1.01)]
    frac = np.array([s["frac"] for s in sw], float)
    vs = np.array([s["v"] for s in sw], float)
    sweep_rows = []
    for lo, hi in bins:
        sel = (frac >= lo) & (frac < hi) & np.isfinite(vs)
        sweep_rows.append({"fraction_from": None if lo == -np.inf else lo, "fraction_to": hi, "n": int(sel.sum()),
                           "rms_v": float(np.sqrt(np.mean(vs[sel] ** 2))) if sel.any() else None})
    return {"calibration": calibration, "table1": table1, "excitation_sweep": sweep_rows,
            "sweep_points": [[float(f), float(v)] for f, v in zip(frac, vs) if np.isfinite(f) and np.isfinite(v)],
            "refine_iterations": {"noise_1mm": it1, "noise_3mm": it3},
            "time_s": {"calibration": t_cal, "table1": t_t1, "total": time.perf_counter() - t0}}


# ---------------------------------------------------------------------- output
def fmt(x, spec=".3f"):
    return "   -  " if x is None else format(x, spec)


def report(res: dict, trials: int, t1_trials: int) -> None:
    print(f"1. Calibration against the true centre ({trials} trials per scenario; noise estimated). "
          f"Calibrated: mean v {EXPECTED_MEAN_V:.3f}, RMS v 1, P(e > χ²₃,95%) 0.05")
    head = f"{'scenario':<24} {'method':<10} {'mean v':>12} {'RMS v':>7} {'P>95%':>6} {'unc mm':>8} {'RMS err':>8} {'σ̂ mm':>6} {'ρ̂':>6}"
    print(head)
    print("-" * len(head))
    for name, per in res["calibration"].items():
        for m, s in per.items():
            print(f"{name:<24} {m:<10} {fmt(s['mean_v'])}±{fmt(s['mean_v_se'], '.3f')} {fmt(s['rms_v'], '7.3f')} "
                  f"{fmt(s['p_exceed_95'], '6.3f')} {fmt(s['median_uncertainty_mm'], '8.3f')} "
                  f"{fmt(s['rms_error_mm'], '8.3f')} {fmt(s['noise_mm'], '6.3f')} {fmt(s['residual_autocorr'], '6.2f')}")
    print(f"\n2. Table 1 (rig, 60 Hz, first Nt frames of 20 s; {t1_trials} trials; σ = 1 mm, √tr Wy = 1.73 mm)")
    head = (f"{'Nt':>5} | {'paper √trW':>10} {'paper v':>7} | {'this √trW':>10} {'RMS err':>8} {'v(true)':>7} "
            f"{'v(1200)':>7} {'det':>4} | {'eq9 √trW':>9} {'v(true)':>7} {'v(1200)':>7}")
    print(head)
    print("-" * len(head))
    for row in res["table1"]:
        a, b = row["this"], row["paper"]
        print(f"{row['n_frames']:>5} | {row['paper_sqrt_tr_mm']:>10.2f} {fmt(row['paper_v'], '7.2f')} | "
              f"{a['median_sqrt_tr_mm']:>10.3g} {fmt(a['rms_error_mm'], '8.3g')} {fmt(a['mean_v'], '7.2f')} "
              f"{fmt(a['mean_v_vs_1200'], '7.2f')} {a['n_determined']:>4} | {b['median_sqrt_tr_mm']:>9.3g} "
              f"{fmt(b['mean_v'], '7.2f')} {fmt(b['mean_v_vs_1200'], '7.2f')}")
    print("\n3. Excitation sweep: RMS v (finite linearised covariance) by information fraction")
    for r in res["excitation_sweep"]:
        lo = "-inf" if r["fraction_from"] is None else f"{r['fraction_from']:.2f}"
        print(f"   [{lo:>5}, {r['fraction_to']:.2f}): n {r['n']:>3}  RMS v {fmt(r['rms_v'], '.2f')}")
    print(f"   (INFO_OK = {INFO_OK}, INFO_FAIL = {INFO_FAIL})")
    it = res["refine_iterations"]
    print(f"\n4. eq. (5) iterations to 15 digits: σ = 1 mm: max {max(it['noise_1mm'])}; σ = 3 mm: max {max(it['noise_3mm'])}")


def figure(res: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(12, 9))
    nt = np.array([r["n_frames"] for r in res["table1"]])
    a = ax[0, 0]
    for m, col, lab in (("this", "C0", "this (6 unknowns, corrected)"), ("paper", "C1", "eq. 9 as printed")):
        med = np.array([r[m]["median_sqrt_tr_mm"] for r in res["table1"]])
        fin = np.isfinite(med)
        a.plot(nt[fin], med[fin], "o-", color=col, label=f"{lab}: median √tr Wc")
    err = np.array([np.nan if r["this"]["rms_error_mm"] is None else r["this"]["rms_error_mm"] for r in res["table1"]])
    a.plot(nt, err, "s--", color="C0", alpha=0.6, label="this: RMS true error")
    err_p = np.array([np.nan if r["paper"]["rms_error_mm"] is None else r["paper"]["rms_error_mm"] for r in res["table1"]])
    a.plot(nt, err_p, "s--", color="C1", alpha=0.6, label="eq. 9: RMS true error")
    a.plot(nt, [r["paper_sqrt_tr_mm"] for r in res["table1"]], "k^:", label="seed 001 Table 1")
    a.set(xscale="log", yscale="log", xlabel="frames Nt (60 Hz)", ylabel="mm", title="Table 1: uncertainty vs frames")
    a.legend(fontsize=7)
    a = ax[0, 1]
    for m, col in (("this", "C0"), ("paper", "C1")):
        v = [np.nan if r[m]["mean_v"] is None else r[m]["mean_v"] for r in res["table1"]]
        vr = [np.nan if r[m]["mean_v_vs_1200"] is None else r[m]["mean_v_vs_1200"] for r in res["table1"]]
        a.plot(nt, v, "o-", color=col, label=f"{m}: v vs truth")
        a.plot(nt, vr, "x--", color=col, label=f"{m}: v vs own 1200-frame fit")
    a.plot(nt, [np.nan if r["paper_v"] is None else r["paper_v"] for r in res["table1"]], "k^:", label="seed 001 Table 1")
    a.axhline(EXPECTED_MEAN_V, color="grey", lw=0.8)
    a.set(xscale="log", yscale="log", xlabel="frames Nt", ylabel="mean validation index v",
          title="Table 1: validation index (grey: calibrated, 0.921)")
    a.legend(fontsize=7)
    a = ax[1, 0]
    names = list(res["calibration"])
    methods = sorted({m for per in res["calibration"].values() for m in per}, key=lambda m: (m != "this", m))
    width = 0.8 / len(methods)
    for k, m in enumerate(methods):
        vals = [res["calibration"][n].get(m, {}).get("rms_v") or np.nan for n in names]
        a.bar(np.arange(len(names)) + k * width, vals, width, label=m)
    a.axhline(1.0, color="k", lw=0.8)
    a.set(yscale="log", ylabel="RMS validation index", title="Calibration against the truth")
    a.set_xticks(np.arange(len(names)) + 0.4 - width / 2, names, rotation=20, fontsize=7, ha="right")
    a.legend(fontsize=7)
    a = ax[1, 1]
    pts = np.array(res["sweep_points"]).reshape(-1, 2)
    a.scatter(np.clip(pts[:, 0], -0.5, 1), pts[:, 1], s=6, alpha=0.4)
    for r in res["excitation_sweep"]:
        if r["rms_v"] is not None and r["fraction_from"] is not None:
            a.hlines(r["rms_v"], r["fraction_from"], r["fraction_to"], color="C3", lw=2)
    a.axvline(INFO_OK, color="k", ls="--", lw=0.8)
    a.axvline(INFO_FAIL, color="k", ls=":", lw=0.8)
    a.axhline(1.0, color="grey", lw=0.8)
    a.set(yscale="log", xlabel="information fraction (clipped at −0.5)", ylabel="v (red: RMS per bin)",
          title="Excitation sweep: linearised covariance vs real excitation")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def jsonable(x):
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return None if np.isnan(x) else ("inf" if x > 0 else "-inf")
    if isinstance(x, (np.floating, np.integer)):
        return jsonable(x.item())
    return x


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=200, help="trials per calibration scenario (default 200)")
    ap.add_argument("--table1-trials", type=int, default=60, help="20 s trials for Table 1 (default 60)")
    ap.add_argument("--sweep", type=int, default=300, help="trials of the excitation sweep (default 300)")
    ap.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    ap.add_argument("--quick", action="store_true", help="20/6/60 trials; writes nothing unless --out")
    ap.add_argument("--out", type=Path, default=None, help="JSON to update (default benchmarks/results.json)")
    args = ap.parse_args(argv)
    if args.quick:
        args.trials, args.table1_trials, args.sweep = 20, 6, 60
    out = args.out or (None if args.quick else ROOT / "benchmarks" / "results.json")
    res = run(args.trials, args.table1_trials, args.sweep, args.workers)
    report(res, args.trials, args.table1_trials)
    print(f"\ntotal {res['time_s']['total']:.1f} s")
    if out is not None:
        doc = {"description": __doc__.split("\n\n")[0], **jsonable(res),
               "expected_mean_v": EXPECTED_MEAN_V, "chi2_3_95": CHI2_95,
               "settings": {"trials": args.trials, "table1_trials": args.table1_trials, "sweep": args.sweep,
                            "scenarios": {n: {"model": s[0].source, "joint": s[1], "n_frames": s[2], "rate_hz": s[3],
                                              "noise_mm": s[4], "rom_deg": s[5], "n_axes": s[6], "occlusion": s[7],
                                              "ar1_rho": s[8]} for n, s in SCENARIOS.items()},
                            "methods": METHODS, "info_ok": INFO_OK, "info_fail": INFO_FAIL},
               "machine": machine_info(), "date": datetime.datetime.now().isoformat(timespec="seconds")}
        write_json(out, KEY, doc, merge=True)
        fig_path = FIGURE if out == ROOT / "benchmarks" / "results.json" else out.with_suffix(".png")
        figure(res, fig_path)
        print(f"wrote {out} (key {KEY!r}) and {fig_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
