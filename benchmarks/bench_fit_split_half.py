"""Split-half consistency of ``fit`` on the real recordings: the two halves of a trial, fitted apart, should
agree within their combined 95 % intervals, if the intervals are honest about the trial's noise and misfit.

For each recording and its dense model (examples/real_*.toml), ``identcheck.fit`` runs on the first and on
the second half of the frames that move (the hip trial is still after 13.5 s: frames 0-1349). A marker
distance is consistent when ``|d1 − d2| ≤ 1.96 sqrt(se1² + se2²)``; reported per joint: the share of its
marker distances that are, the largest |d1 − d2| and its combined half-width, and the verdicts.

Usage::

    PYTHONPATH=. python benchmarks/bench_fit_split_half.py [--data DIR]
"""
from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import identcheck as ic  # noqa: E402
from identcheck.trial import Trial  # noqa: E402
from results_io import machine_info, write_json  # noqa: E402

RUNS = [  # (recording, model, frames that move)
    ("biobuddy_right_hip.c3d", "real_right_hip.toml", (0, 1350)),
    ("biobuddy_right_knee.c3d", "real_right_knee.toml", None),
    ("opensim_walking2.c3d", "real_walking2_legs.toml", None),
    ("opensim_subject01_walk1.trc", "real_walk_leg.toml", None),
]


def _half(trial: Trial, a: int, b: int) -> Trial:
    return Trial(trial.as_array()[a:b], trial.labels, trial.rate_hz, f"{trial.source}[{a}:{b}]")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path(os.environ.get("IDENTCHECK_REAL_DATA", "/work/shared/data/real")))
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results.json")
    a = ap.parse_args(argv)
    out = {}
    print(f"{'recording':<30} {'joint':<8} {'consistent':>10} {'max |d1-d2|':>12} {'its 95% bound':>14}  verdicts")
    for rec, model_file, span in RUNS:
        path = a.data / rec
        if not path.exists():
            print(f"{rec}: not found, skipped", file=sys.stderr)
            continue
        trial = ic.read_trial(path)
        lo, hi = span or (0, trial.n_frames)
        mid = (lo + hi) // 2
        model = ic.load_model(ROOT / "examples" / model_file)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            halves = [ic.fit(model, _half(trial, s, e)).to_dict() for s, e in ((lo, mid), (mid, hi))]
        for joint in halves[0]["joints"]:
            j1, j2 = halves[0]["joints"][joint], halves[1]["joints"][joint]
            ci1, ci2 = j1.get("marker_distances_ci95", {}), j2.get("marker_distances_ci95", {})
            rows = []
            for m in ci1:
                if m not in ci2 or j1["marker_distances"].get(m) is None or j2["marker_distances"].get(m) is None:
                    continue
                if ci1[m][1] is None or ci2[m][1] is None:       # an unbounded interval holds any other answer
                    continue
                se1, se2 = (ci1[m][1] - ci1[m][0]) / (2 * 1.96), (ci2[m][1] - ci2[m][0]) / (2 * 1.96)
                diff = abs(j1["marker_distances"][m] - j2["marker_distances"][m])
                bound = 1.96 * float(np.hypot(se1, se2))
                rows.append((m, diff, bound, diff <= bound))
            if not rows:
                continue
            worst = max(rows, key=lambda r: r[1])
            share = float(np.mean([r[3] for r in rows]))
            verdicts = [j1["practical"]["verdict"], j2["practical"]["verdict"]]
            out[f"{rec}:{joint}"] = {"model": model_file, "frames": [lo, mid, hi], "consistent_share": round(share, 3),
                                     "max_difference_mm": round(worst[1], 2), "its_bound_mm": round(worst[2], 2),
                                     "marker": worst[0], "verdicts": verdicts}
            print(f"{rec:<30} {joint:<8} {share:>10.2f} {worst[1]:>12.2f} {worst[2]:>14.2f}  {verdicts}")
    write_json(a.out, "fit_split_half", {"runs": out, "machine": machine_info()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
