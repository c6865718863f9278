"""benchmarks/bench_second_rotation_fit.py: both derivatives of a ball knee's profiles are fitted on the same draws,
the package's (the left Jacobian) needs no more iterations than the profile's own axis and ends no higher, the
derivative it swaps in for the comparison is put back, and results.json's other keys are kept."""
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
bench = pytest.importorskip("bench_second_rotation_fit")


def test_both_derivatives_fitted_side_by_side(tmp_path):
    import identcheck.bundle.jacobian as jacobian
    from identcheck.geometry.rotations import left_jacobian_times

    out = tmp_path / "results.json"
    out.write_text(json.dumps({"other": {"kept": True}}))
    assert bench.main(["--draws", "2", "--frames", "400", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["other"] == {"kept": True}
    s = data["second_rotation_fit"]["summary"]
    assert s["left Jacobian"]["converged"] == 2
    assert s["left Jacobian"]["max_iterations"] <= s["own axis"]["max_iterations"]
    assert all(r["rss_own_minus_left"] > -1e-6 * r["left Jacobian"]["rss"] for r in data["second_rotation_fit"]["rows"])
    assert jacobian.left_jacobian_times is left_jacobian_times
