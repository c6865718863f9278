"""benchmarks/bench_fit_compare.py --quick: every fitting method is exact without noise, worse with it."""
import json
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow      # the fast lane (pytest -m 'not slow') leaves these out

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
bench = pytest.importorskip("bench_fit_compare")

ZERO_NOISE_TOL = {"err_mm": 1e-6, "angle_deg": 1e-6, "pos_mm": 1e-6}
LOOSER = {"Pham 2,1": 1e-5}    # geometric least squares from the closed-form seeds (ODR tolerance)
GATED_AT_4MM = {("hinge", "O'Brien")}   # axis only for single-axis motion: 4 mm of noise spreads > 2 deg


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("fit_compare") / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main(["--quick", "--trials", "2", "--out", str(out)]) == 0
    return json.loads(out.read_text()), out


def _row(doc, kind, noise):
    return next(r for r in doc[kind]["grids"]["noise"] if r["value"] == noise)


def test_json_has_the_key_and_every_method(quick):
    data, out = quick
    assert data["other"] == {"kept": True}           # other keys survive
    assert "fit_compare" not in data                 # a quick run never overwrites the full one
    doc = data["fit_compare_quick"]
    assert doc["settings"]["quick"] and doc["settings"]["trials"] == 2
    for kind, methods in bench.METHODS.items():
        assert set(doc["settings"]["methods"][kind]) == set(methods)
        for grid, rows in doc[kind]["grids"].items():
            assert [r["value"] for r in rows] == list(bench.QUICK_GRIDS[grid])
            for row in rows:
                assert set(row["methods"]) == set(methods)
        assert set(doc[kind]["timing"]["all_trials"]) == set(methods)
        fastest = min(e["median_s"] for e in doc[kind]["timing"]["all_trials"].values())
        assert fastest > 0
    assert out.with_suffix(".png").stat().st_size > 10_000


@pytest.mark.parametrize("kind", list(bench.METHODS))
def test_exact_without_noise_and_worse_with_it(quick, kind):
    doc = quick[0]["fit_compare_quick"]
    zero, four = _row(doc, kind, 0.0), _row(doc, kind, 4.0)
    keys = ("err_mm",) if kind == "spherical" else ("angle_deg", "pos_mm")
    for name in bench.METHODS[kind]:
        m0, m4 = zero["methods"][name], four["methods"][name]
        assert m0["n"] >= 1 and m0["n_fail"] == 0, (name, m0["fail_messages"])
        for key in keys:
            tol = LOOSER.get(name, ZERO_NOISE_TOL[key])
            assert m0[key]["max"] < tol, (kind, name, key, m0[key])
            if (kind, name) in GATED_AT_4MM:
                assert m4["n_fail"] == m4["n"], (name, m4)
                continue
            assert m4["n_fail"] < m4["n"], (name, m4["fail_messages"])
            assert m4[key]["mean"] > max(100 * tol, m0[key]["mean"]), (kind, name, key, m4[key])


def test_loops_match_their_vectorised_methods(quick):
    """The per-frame Python loops solve the same least-squares problems as SCoRE / SARA."""
    doc = quick[0]["fit_compare_quick"]
    for kind, a, b, key in (("spherical", "SCoRE", "SCoRE loop", "err_mm"), ("spherical", "SCoRE", "O'Brien", "err_mm"),
                            ("hinge", "SARA", "SARA loop", "angle_deg"), ("hinge", "SARA", "SARA loop", "pos_mm")):
        for row in doc[kind]["grids"]["noise"]:
            x, y = row["methods"][a][key]["mean"], row["methods"][b][key]["mean"]
            assert abs(x - y) <= 1e-6 * (1 + abs(x)), (kind, a, b, row["value"], x, y)
