"""``diagnose``'s detection limits: from what size is each effect named, as a function of the noise and the trial's length?

The trials are the independent generator's sweep (``benchmarks/heldout_effects/generator.py --sweep all``, written
by an author who never read the detectors): one effect each, its size drawn log-uniform from far below what any
method could see up to large, the noise's level (0.3-1.5 mm) and correlation (white or AR(1)) and the trial's
length (500-3000 frames) drawn at random, with the v2 motions, marker layouts and occlusion gaps. Each trial is
diagnosed (``bench_diagnose_heldout.evaluate``: the effect is *named* when ``diagnose`` names it first).

Per effect, the chance of naming it is fitted by logistic regression on the log of its size, the log of the noise,
the log of the length and the noise's correlation (one model per effect; the coefficients are reported, and a
visible χ² argument says they should be about b, -b, b/2: what a rigid model cannot absorb grows as
size² × frames / noise²). The size from which the fit names the effect in 90 % of trials is tabulated for a grid of
noises and lengths, with a bootstrap interval over the trials; the table also says how many trials lay above that
size and what share of them were named, so the fit's claim can be checked against the raw counts. Sizes are the
realised peak displacement in mm, except for a knee's extra rotation (degrees), a delay (ms) and a swap (frames).

Usage::

    python benchmarks/heldout_effects/generator.py --out /tmp/sw --n 40 --seed S --version 2 --sweep all
    python benchmarks/bench_detection_limits.py /tmp/sw --shard 0/2 --rows /tmp/r0.json   # and 1/2
    python benchmarks/bench_detection_limits.py /tmp/sw --merge /tmp/r0.json /tmp/r1.json --key KEY
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from results_io import add_shard_arguments, machine_info, run_trials, write_json  # noqa: E402

RATE = 0.9
NOISES_MM = (0.3, 0.5, 1.0, 1.5)
LENGTHS = (500, 1000, 2000)
BOOTSTRAP = 200
PRIOR_SD = 10.0          # a weak Gaussian prior on the slopes: a perfectly separated draw still has a finite fit

# Each effect's size as a lab states it: (row key or size name, unit, factor to that unit).
UNITS = {"extra_dof": ("amplitude_deg", "deg", 1.0), "time_offset": ("lag_frames", "ms", 10.0),
         "marker_swap": ("span_frames", "frames", 1.0)}


def size_of(row: dict) -> float | None:
    """The effect's size in the unit of :data:`UNITS` (realised peak displacement in mm by default)."""
    name = row["truth"][0]
    if name in UNITS:
        size = row.get("size") or {}
        return None if size.get("value") is None else float(size["value"]) * UNITS[name][2]
    return row["magnitudes"][0]


def unit_of(name: str) -> str:
    return UNITS.get(name, (None, "mm", 1.0))[1]


def evaluate(trial_dir: Path, entry: dict) -> dict:
    """``diagnose`` on one sweep trial (:func:`bench_diagnose_heldout.evaluate`), with the trial's noise, length and
    the effect's size parameter beside it."""
    import bench_diagnose_heldout as heldout

    row = heldout.evaluate(trial_dir, entry)
    params = entry.get("params", {})
    noise = params.get("noise", {})
    row.update({"frames": params.get("frames"), "sigma_mm": noise.get("sigma_mm"), "phi": noise.get("phi"),
                "noise_kind": noise.get("kind"), "size": entry["effects"][0].get("size")})
    return row


def design(size, sigma, frames, ar1) -> np.ndarray:
    """The regression's columns: 1, log size, log noise, log length, AR(1) noise (0/1)."""
    size, sigma, frames, ar1 = np.broadcast_arrays(*(np.asarray(v, float) for v in (size, sigma, frames, ar1)))
    return np.stack([np.ones(size.shape), np.log(size), np.log(sigma), np.log(frames), ar1], axis=-1)


def fit_logistic(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Maximum a-posteriori logistic coefficients (the slopes under a N(0, PRIOR_SD²) prior, the intercept flat),
    by Newton's method on the concave log posterior."""
    from scipy.special import expit

    beta = np.zeros(X.shape[1])
    prec = np.full(X.shape[1], PRIOR_SD ** -2)
    prec[0] = 0.0
    for _ in range(100):
        p = expit(X @ beta)
        grad = X.T @ (y - p) - prec * beta
        hess = (X * (p * (1 - p))[:, None]).T @ X + np.diag(prec)
        step = np.linalg.solve(hess + 1e-12 * np.eye(len(beta)), grad)
        beta = beta + step
        if np.max(np.abs(step)) < 1e-10:
            break
    return beta


def limit_size(beta: np.ndarray, sigma: float, frames: float, ar1: float, rate: float = RATE) -> float | None:
    """The size at which the fitted chance of naming reaches `rate` (None when the fit does not rise with size)."""
    if beta[1] <= 0:
        return None
    other = design(1.0, sigma, frames, ar1) @ beta          # log size = 0 there
    return float(np.exp((np.log(rate / (1 - rate)) - other) / beta[1]))


def effect_rows(rows: list, name: str) -> tuple:
    """The trials of one effect that ran and have a size: the rows, the design matrix and whether it was named."""
    keep = [r for r in rows if "error" not in r and r["truth"][0] == name and size_of(r) and r.get("sigma_mm")
            and r.get("frames")]
    X = design([size_of(r) for r in keep], [r["sigma_mm"] for r in keep], [r["frames"] for r in keep],
               [r["noise_kind"] == "ar1" for r in keep]) if keep else np.zeros((0, 5))
    y = np.array([bool(r["named"]) and r["named"][0] == name for r in keep], float)
    return keep, X, y


def summarise_effect(rows: list, name: str, seed: int = 0) -> dict:
    """One effect: the fitted coefficients, the 90 % limits on the grid (white and AR(1) noise) with bootstrap
    intervals, and the raw share named above each trial's own fitted limit."""
    keep, X, y = effect_rows(rows, name)
    out = {"trials": len(keep), "named": int(y.sum()), "unit": unit_of(name)}
    sizes = [size_of(r) for r in keep]
    if keep and y.sum() == len(y):
        out["note"] = f"named in every trial, down to the smallest size drawn ({min(sizes):.3g} {out['unit']})"
        return out
    if keep and y.sum() == 0:
        out["note"] = f"named in no trial, up to the largest size drawn ({max(sizes):.3g} {out['unit']})"
        return out
    if len(keep) < 8:
        out["note"] = "fewer than 8 trials: no limit fitted"
        return out
    beta = fit_logistic(X, y)
    rng = np.random.default_rng(seed)
    boots = []
    for _ in range(BOOTSTRAP):
        k = rng.integers(0, len(y), len(y))
        boots.append(fit_logistic(X[k], y[k]))
    lo, hi = min(sizes), max(sizes)           # a limit outside the sizes drawn is the fitted curve's extrapolation
    grid = []
    for kind, ar1 in (("white", 0.0), ("ar1", 1.0)):
        for sigma in NOISES_MM:
            for frames in LENGTHS:
                lim = limit_size(beta, sigma, frames, ar1)
                bl = [limit_size(b, sigma, frames, ar1) for b in boots]
                bl = [v for v in bl if v is not None and np.isfinite(v)]
                grid.append({"noise": kind, "sigma_mm": sigma, "frames": frames,
                             "limit": None if lim is None else round(lim, 3),
                             "extrapolated": lim is None or not lo <= lim <= hi,
                             "ci95": [round(float(np.quantile(bl, 0.025)), 3), round(float(np.quantile(bl, 0.975)), 3)]
                             if len(bl) >= BOOTSTRAP // 2 else None})
    own = [limit_size(beta, r["sigma_mm"], r["frames"], float(r["noise_kind"] == "ar1")) for r in keep]
    above = [bool(v) for v, lim, r in zip(y, own, keep) if lim is not None and size_of(r) >= lim]
    below = [bool(v) for v, lim, r in zip(y, own, keep) if lim is not None and size_of(r) < lim]
    out.update({"coefficients": dict(zip(["intercept", "log_size", "log_noise", "log_frames", "ar1"],
                                         np.round(beta, 3).tolist())),
                "grid": grid,
                "above_own_limit": {"trials": len(above), "named": int(sum(above))},
                "below_own_limit": {"trials": len(below), "named": int(sum(below))},
                "trials_detail": [[round(size_of(r), 3), r["sigma_mm"], r["frames"], r["noise_kind"], bool(v),
                                   r["named"][:3]] for r, v in zip(keep, y)]})
    return out


def summarise(rows: list) -> dict:
    names = sorted({r["truth"][0] for r in rows if "error" not in r and r.get("truth")})
    return {"effects": {n: summarise_effect(rows, n) for n in names}, "trials": len(rows),
            "errors": sum("error" in r for r in rows), "rate": RATE,
            "median_seconds": float(np.median([r["seconds"] for r in rows])) if rows else None}


def table(summary: dict) -> str:
    """Per effect: its coefficients, and the size named in 90 % of trials for each noise and length."""
    lines = [f"{summary['trials']} trials, {summary['errors']} errors; size named first in {RATE:.0%} of trials "
             f"(bootstrap 95 % interval), by noise and trial length; * outside the sizes drawn"]
    for name, e in summary["effects"].items():
        lines.append("")
        lines.append(f"{name} ({e['trials']} trials, {e['named']} named; size in {e['unit']})")
        if "grid" not in e:
            lines.append(f"  {e['note']}")
            continue
        c = e["coefficients"]
        lines.append("  logit = {intercept} + {log_size} log size + {log_noise} log noise + {log_frames} log frames "
                     "+ {ar1} ar1".format(**c))
        a, b = e["above_own_limit"], e["below_own_limit"]
        lines.append(f"  raw: named {a['named']}/{a['trials']} above their fitted limit, {b['named']}/{b['trials']} "
                     "below")
        lines.append(f"  {'noise':<12}" + "".join(f"{f'{n} frames':>24}" for n in LENGTHS))
        for kind in ("white", "ar1"):
            for sigma in NOISES_MM:
                cells = [g for g in e["grid"] if g["noise"] == kind and g["sigma_mm"] == sigma]
                lines.append(f"  {kind} {sigma:<6g}" + "".join(
                    f"{_cell(g):>24}" for g in cells))
    return "\n".join(lines)


def _cell(g: dict) -> str:
    """A grid cell: the limit with its interval; ``*`` marks a limit outside the sizes drawn (extrapolated)."""
    if g["limit"] is None:
        return "-"
    ci = g["ci95"]
    star = "*" if g.get("extrapolated") else ""
    return f"{star}{g['limit']:.3g} [{ci[0]:.3g}, {ci[1]:.3g}]" if ci else f"{star}{g['limit']:.3g}"


def figure(summary: dict, path: Path) -> None:
    """One panel per effect: each trial's size against its noise per √(frames/1000) (what a white-noise visible χ²
    depends on), named filled, missed open, and the fitted 90 % limit at 1000 frames, white and AR(1) noise."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    effects = [(n, e) for n, e in summary["effects"].items() if "trials_detail" in e]
    cols = 4
    rows_n = max(1, -(-len(effects) // cols))
    fig, axes = plt.subplots(rows_n, cols, figsize=(4 * cols, 3.4 * rows_n), squeeze=False)
    for ax, (name, e) in zip(axes.flat, effects):
        det = e["trials_detail"]
        eff = np.array([d[1] * np.sqrt(1000.0 / d[2]) for d in det])
        size = np.array([d[0] for d in det])
        hit = np.array([d[4] for d in det])
        ar1 = np.array([d[3] == "ar1" for d in det])
        for mask, mk in ((~ar1, "o"), (ar1, "s")):
            ax.scatter(eff[mask & hit], size[mask & hit], marker=mk, color="tab:green", s=18)
            ax.scatter(eff[mask & ~hit], size[mask & ~hit], marker=mk, facecolors="none", edgecolors="tab:red", s=18)
        beta = np.array(list(e["coefficients"].values()))
        s_grid = np.geomspace(0.2, 3.0, 30)
        for a1, ls in ((0.0, "-"), (1.0, "--")):
            lims = [limit_size(beta, s, 1000, a1) for s in s_grid]
            ax.plot(s_grid, [np.nan if v is None else v for v in lims], "k" + ls, lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks([0.2, 0.5, 1.0, 2.0])                  # plain numbers: minor log labels overlapped
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("noise σ·√(1000/frames) [mm]", fontsize=8)
        ax.set_ylabel(f"size [{e['unit']}]", fontsize=8)
    for ax in list(axes.flat)[len(effects):]:
        ax.axis("off")
    fig.suptitle("diagnose: named first (filled) or missed (open); circles white noise, squares AR(1); "
                 "lines: fitted 90 % limit at 1000 frames (solid white, dashed AR(1))", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trials", type=Path)
    add_shard_arguments(ap)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    ap.add_argument("--key", default="diagnose_detection_limits")
    ap.add_argument("--figure", type=Path, default=None, help="where the figure goes (default: beside --out)")
    a = ap.parse_args(argv)
    index = json.loads((a.trials / "index.json").read_text())
    if not index.get("sweep"):
        raise SystemExit(f"{a.trials / 'index.json'}: not a sweep draw (generator.py --sweep)")
    rows = run_trials(index["trials"], lambda e: evaluate(a.trials, e), a, lambda k, n, e, r: (
        f"[{k}/{n}] {r['stem']} {r.get('truth')} size {r.get('size')} named {r.get('named')} {r['seconds']:.0f}s"
        + (f" ERROR {r['error']}" if "error" in r else "")))
    if rows is None:
        return 0
    summary = summarise(rows)
    print(table(summary))
    try:
        figure(summary, a.figure or a.out.parent / f"{a.key}.png")
    except ImportError:
        print("matplotlib missing: no figure", file=sys.stderr)
    write_json(a.out, a.key, {"summary": summary, "rows": rows, "machine": machine_info(), "source": {
        "folder": str(a.trials), "generator": index.get("generator"), "seed": index.get("seed"), "n": index.get("n")}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
