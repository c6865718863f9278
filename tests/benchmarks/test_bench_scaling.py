"""benchmarks/bench_scaling.py: the models it sweeps are valid and as large as it says, the exponent it fits is the
power of a power law, and one fit worker and one diagnose run on a small simulated trial report what the sweep
tabulates."""
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
bench = pytest.importorskip("bench_scaling")


@pytest.mark.parametrize("per_segment,legs_only,segments,joints", [(3, True, 7, 6), (3, False, 14, 13),
                                                                    (5, False, 14, 13)])
def test_body_models_have_the_segments_joints_and_markers_said(tmp_path, per_segment, legs_only, segments, joints):
    from identcheck.io.model import Model

    path = tmp_path / "body.toml"
    path.write_text(bench.body_model(per_segment, legs_only=legs_only))
    model = Model.from_toml(path)
    assert len(model.segments) == segments and len(model.joints) == joints
    assert len(model.markers) == per_segment * segments == len(set(model.markers))


@settings(max_examples=40, deadline=None)
@given(st.floats(-2.0, 3.0), st.floats(1e-3, 1e3), st.lists(st.integers(2, 10_000), min_size=2, max_size=6,
                                                           unique=True))
def test_slope_is_the_power_of_a_power_law(power, scale, xs):
    ys = [scale * x ** power for x in xs]
    assert bench.slope(xs, ys) == pytest.approx(power, abs=1e-6)


def test_slope_leaves_out_missing_points_and_needs_two():
    assert bench.slope([1, 2, 4], [1.0, None, 16.0]) == pytest.approx(2.0)
    assert bench.slope([1, 2], [1.0, None]) is None


def test_one_point_measured_end_to_end(tmp_path):
    root = bench.ROOT
    model, trial, n_markers = bench.write_trial(tmp_path, "leg9 120 frames", 120,
                                                (root / "examples" / "diagnose_leg.toml").read_text())
    assert n_markers == 9 and model.exists() and trial.exists()
    fit = bench.run_fit(root, model, trial, 2)
    assert "error" not in fit, fit
    assert 1 <= fit["iterations"] <= 2 and fit["s_per_iteration"] > 0 and np.isfinite(fit["rss_mm2"])
    diag = bench.run_diagnose(root, model, trial, cap_s=300.0)
    assert diag["exit_code"] in (0, 1) and diag["cpu_s"] > 0 and isinstance(diag["effects"], list)
    capped = bench.run_diagnose(root, model, trial, cap_s=0.0)
    assert capped.get("capped") is True and "cpu_s" not in capped


@settings(max_examples=20, deadline=None)
@given(st.floats(0.5, 2.5), st.floats(0.5, 2.5), st.floats(0.0, 2.0))
def test_exponents_are_the_powers_each_version_and_diagnose_grow_with(p_base, p_now, startup):
    """Rows whose times are power laws of the frames (the fit's per iteration, the diagnose process's as a startup
    cost plus a power law): the exponents read back are those powers, diagnose's once the startup is taken off."""
    rows = []
    for n in (500, 1000, 2000, 4000, 8000):
        fit = lambda p: {"s_per_iteration": 1e-5 * n ** p}  # noqa: E731
        rows.append({"sweep": "frames", "frames": n, "markers": 9,
                     "baseline": {"fit": fit(p_base), "diagnose": {}},
                     "current": {"fit": fit(p_now), "diagnose": {"cpu_s": startup + 1e-4 * n ** p_now}}})
    exps = bench.exponents(rows, startup)
    assert exps["frames/fit_s_per_iteration/baseline"] == pytest.approx(p_base, abs=1e-6)
    assert exps["frames/fit_s_per_iteration/current"] == pytest.approx(p_now, abs=1e-6)
    assert exps["frames/diagnose_cpu_s_less_startup/current"] == pytest.approx(p_now, abs=1e-6)
    assert exps["frames/diagnose_cpu_s_less_startup_upper_half/current"] == pytest.approx(p_now, abs=1e-6)
    assert exps["markers/fit_s_per_iteration/current"] is None


def test_the_lm_benchmarks_body42_is_this_body_with_lab_marker_names(tmp_path):
    """bench_lm_iteration's ``body42`` is built by :func:`bench_scaling.body_model` (one body for both benchmarks):
    the same segments, lengths and joints as the three-marker body here, its markers named as in a lab."""
    import bench_lm_iteration
    from identcheck.io.model import Model

    (tmp_path / "lab.toml").write_text(bench_lm_iteration.body42())
    (tmp_path / "here.toml").write_text(bench.body_model(3))
    lab, here = Model.from_toml(tmp_path / "lab.toml"), Model.from_toml(tmp_path / "here.toml")
    assert list(lab.segments) == list(here.segments) and list(lab.joints) == list(here.joints)
    assert all(lab.segments[s].length_mm == here.segments[s].length_mm for s in lab.segments)
    assert all(lab.joints[j] == here.joints[j] for j in lab.joints)
    assert {"RGT", "LHN2", "SACR"} <= set(lab.markers) and len(lab.markers) == 42
