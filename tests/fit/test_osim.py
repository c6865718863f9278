"""``fit --export-osim``: the OpenSim model places every marker where the whole-tree fit does, for any hinge angles
(read back and posed by OpenSim itself), and the pin joints' frames carry the fit's relative rotation exactly."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from identcheck.fit.osim import hinge_frames, opensim_missing

ROOT = Path(__file__).resolve().parents[2]


def _rot(axis, theta):
    return Rotation.from_rotvec(theta * np.asarray(axis)).as_matrix()


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), theta=st.floats(-3.1, 3.1))
def test_pin_frames_carry_the_fits_relative_rotation(seed, theta):
    """F_p Rot(z, θ) F_cᵀ = Rot(axis, θ) rest for a random axis and rest rotation; F_p's z is the axis."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    rest = Rotation.random(random_state=rng.integers(2**31)).as_matrix()
    F_p, F_c = hinge_frames(axis, rest)
    np.testing.assert_allclose(F_p.T @ F_p, np.eye(3), atol=1e-12)
    assert np.linalg.det(F_p) > 0 and np.linalg.det(F_c) > 0
    np.testing.assert_allclose(F_p[:, 2], axis, atol=1e-12)
    np.testing.assert_allclose(F_p @ _rot([0, 0, 1], theta) @ F_c.T, _rot(axis, theta) @ rest, atol=1e-12)


@pytest.mark.skipif(bool(opensim_missing()), reason="OpenSim's Python package is not installed (identcheck[osim])")
def test_opensim_poses_the_markers_where_the_fit_does(tmp_path):
    import opensim as osim

    from identcheck.bundle.model import forward
    from identcheck.fit.osim import export_osim
    from identcheck.fit.workflow import fit_trial
    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate

    model = Model.from_toml(ROOT / "examples" / "leg.toml")
    sim = simulate(model, n_frames=300, noise_mm=0.5, seed=5)
    got = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit_trial(model, sim.trial, on_fit=lambda t, fit, offset: got.update(fit=fit))
    fit = got["fit"]
    path = tmp_path / "leg.osim"
    export_osim(path, fit)
    om = osim.Model(str(path))
    state = om.initSystem()
    chain = fit.chain
    assert sorted(om.getBodySet().get(i).getName() for i in range(om.getBodySet().getSize())) == sorted(chain.segments)
    kinds = {om.getJointSet().get(i).getName(): om.getJointSet().get(i).getConcreteClassName()
             for i in range(om.getJointSet().getSize())}
    assert kinds == {f"ground_{chain.root}": "FreeJoint",
                     **{j: "BallJoint" if chain.types[j] == "spherical" else "PinJoint" for j in chain.joints}}
    rng = np.random.default_rng(0)
    for _ in range(3):
        s = fit.state.copy()
        s.root_R, s.root_t = np.eye(3)[None], np.zeros((1, 3))
        s.rel_R = {j: np.eye(3)[None] for j in s.rel_R}
        s.theta = {j: rng.uniform(-1.5, 1.5, size=1) for j in s.theta}
        for j, th in s.theta.items():
            om.getCoordinateSet().get(f"{j}_angle").setValue(state, float(th[0]))
        om.realizePosition(state)
        _, _, centre, pred = forward(chain, fit.terms, s)
        for i, label in enumerate(chain.labels):
            p = om.getMarkerSet().get(label).getLocationInGround(state)
            np.testing.assert_allclose([1e3 * p.get(k) for k in range(3)], pred[0, i], atol=1e-6)
        for j in chain.joints:                     # the joint's frame in the parent sits on the fitted centre
            frame = om.getJointSet().get(j).getParentFrame()
            o = frame.getPositionInGround(state)
            np.testing.assert_allclose([1e3 * o.get(k) for k in range(3)], centre[j][0], atol=1e-6)


@pytest.mark.parametrize("problem", ["missing", "suffix"])
def test_export_osim_is_refused_before_any_work(tmp_path, capsys, monkeypatch, problem):
    """Without OpenSim's package, or with a name that is not .osim: exit 2 naming --export-osim and what to do,
    before the fit runs; nothing is written."""
    import identcheck.fit.osim as osim_module
    from identcheck import cli

    trial = tmp_path / "leg.trc"
    assert cli.main(["simulate", str(ROOT / "examples" / "leg.toml"), "--out", str(trial), "--frames", "50"]) == 0
    capsys.readouterr()
    if problem == "missing":
        monkeypatch.setattr(osim_module, "opensim_missing", lambda: "needs OpenSim's Python package, which is not "
                            "installed: pip install 'identcheck[osim]'")
    out = tmp_path / ("leg.osim" if problem == "missing" else "leg.xml")
    assert cli.main(["fit", str(ROOT / "examples" / "leg.toml"), str(trial), "--export-osim", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--export-osim" in err and str(out) in err
    assert ("identcheck[osim]" in err) if problem == "missing" else (".osim" in err)
    assert not out.exists()


@pytest.mark.skipif(bool(opensim_missing()), reason="OpenSim's Python package is not installed (identcheck[osim])")
def test_the_export_leaves_no_opensim_log_where_it_runs(tmp_path, monkeypatch):
    """OpenSim appends to opensim.log in the working folder by default; the export turns that off, so neither
    writing the model nor loading it back leaves a file beside the user's data."""
    import opensim as osim

    from identcheck.fit.osim import export_osim
    from identcheck.fit.workflow import fit_trial
    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate

    monkeypatch.chdir(tmp_path)
    model = Model.from_toml(ROOT / "examples" / "leg.toml")
    got = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit_trial(model, simulate(model, n_frames=100, noise_mm=0.5, seed=1).trial,
                  on_fit=lambda t, fit, offset: got.update(fit=fit))
    export_osim(tmp_path / "leg.osim", got["fit"])
    osim.Model(str(tmp_path / "leg.osim"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["leg.osim"]


@settings(max_examples=40, deadline=None)
@given(st.text(alphabet="abcXYZ_.-0", min_size=1, max_size=6), st.sampled_from(list("\\*+ \t/")),
       st.sampled_from(["segment", "joint", "marker"]))
def test_names_opensim_refuses_are_named_before_the_fit(stem, bad, kind):
    """A segment, joint or marker whose name OpenSim refuses is reported by name (the fit is not run): it had
    stopped OpenSim after the whole fit, with a traceback and then a crash of the process."""
    from identcheck.fit.osim import name_problems
    from identcheck.io.model import Model

    def model(names):
        return Model.from_dict({"units": "mm", "segments": {
            "pelvis": {"markers": ["LASI", "RASI", "SACR"]},
            names["segment"]: {"markers": ["RGT", "RTHI", names["marker"]]}},
            "joints": {names["joint"]: {"type": "spherical", "parent": "pelvis", "child": names["segment"]}}})

    names = {"segment": "thigh", "joint": "hip", "marker": "RKNE"}
    problems = name_problems(model(dict(names, **{kind: stem + bad + stem})))
    assert len(problems) == 1 and problems[0].startswith(f"{kind} {stem + bad + stem!r}")
    assert name_problems(model(dict(names, **{kind: stem + "_" + stem}))) == []
