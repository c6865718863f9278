"""benchmarks/bench_diagnose.py --quick: the table's structure; scipy's sparse least squares agrees with fit_chain."""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow      # the fast lane (pytest -m 'not slow') leaves these out

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
bench = pytest.importorskip("bench_diagnose")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("diagnose") / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main(["--quick", "--out", str(out)]) == 0
    return json.loads(out.read_text())


def test_json_keeps_other_keys_and_never_overwrites_the_full_run(quick):
    assert quick["other"] == {"kept": True}
    assert "diagnose" not in quick
    doc = quick["diagnose_quick"]
    assert doc["settings"]["quick"] and doc["settings"]["repeats"] == 1
    assert doc["machine"]["nproc"] >= 1 and doc["total_s"] > 0


def test_one_row_per_effect(quick):
    doc = quick["diagnose_quick"]
    effects = ["none" if e is None else e for e in bench.QUICK["effects"]]
    assert [r["effect"] for r in doc["rows"]] == effects
    for r in doc["rows"]:
        assert r["frames"] == bench.QUICK["frames"] and r["repeats"] == 1
        assert r["wall_s"] > 0 and r["cpu_s"] > 0 and len(r["all_wall_s"]) == 1
        assert isinstance(r["effects_found"], list) and len(r["where_found"]) == len(r["effects_found"])
        assert r["pass"] == (r["wall_s"] < bench.TARGET_S)
        for k in ("gap_before_mm", "gap_after_mm", "noise_floor_mm"):
            assert math.isfinite(r[k]) and r[k] > 0, (r["effect"], k)
        assert r["gap_after_mm"] <= r["gap_before_mm"] + 1e-9
        assert "default_threads" not in r                 # --quick skips the run with the default BLAS threads
    assert doc["n_pass"] == sum(r["pass"] for r in doc["rows"])


def test_scipy_and_lm_reach_the_same_minimum(quick):
    doc = quick["diagnose_quick"]
    assert [r["frames"] for r in doc["scipy_compare"]] == list(bench.QUICK["scipy_frames"])
    for row in doc["scipy_compare"]:
        lm = row["lm"]
        assert lm["converged"] and lm["wall_s"] > 0 and lm["rss"] > 0
        assert set(row["scipy"]) == set(bench.SCIPY_TOLS)
        for name, s in row["scipy"].items():
            assert not s["capped"] and s["converged"], (name, s)
            assert s["wall_s"] > 0 and s["time_ratio_vs_lm"] > 0
            assert abs(s["rel_rss_diff"]) < 1e-4, (name, s["rss"], lm["rss"])
            assert abs(s["rss_forward"] - s["rss"]) <= 1e-9 * s["rss"]


def test_fit_scaling_rows(quick):
    sc = quick["diagnose_quick"]["fit_scaling"]
    assert [r["frames"] for r in sc["rows"]] == list(bench.QUICK["fit_frames"])
    for r in sc["rows"]:
        assert r["wall_s"] > 0 and r["iterations"] >= 1 and r["s_per_iteration"] > 0
    assert math.isfinite(sc["slope_per_iteration"]) and math.isfinite(sc["slope_total"])


def test_scipy_parametrisation_starts_at_the_initial_state():
    """x = 0 is the starting state, and the sparsity pattern has one frame's columns plus the constants per row."""
    from identcheck.bundle.chain import initial_state
    from identcheck.bundle.model import Terms, forward
    from identcheck.skeleton import Skeleton
    sim = bench.rigid(40)
    m = bench.model()
    chain = Skeleton.from_model(m)
    data = sim.trial.select(m.markers).as_array()
    start = initial_state(chain, data)
    prob = bench.ScipyChain(chain, start, data)
    pred0 = forward(chain, Terms(), start)[3]
    assert np.allclose(prob.residuals(np.zeros(prob.n)), (pred0 - data).reshape(-1), atol=1e-12, rtol=0)
    S = prob.sparsity()
    assert S.shape == (data.size, prob.n)
    assert np.all(np.diff(S.indptr) == prob.k + prob.P)
    assert set(S[:3 * chain.n_markers].indices) == set(range(prob.k)) | set(range(prob.F * prob.k, prob.n))
