"""Degenerate trials through ``identcheck skeleton``: every one ends in a model (exit 0 or 1) or a clear refusal
(exit 2 naming the file); never an internal error (exit 3) or a traceback."""
import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from identcheck import cli
from identcheck.trial import Trial
from strategies_skeleton import make_case

BASE = make_case(21, 3, counts=[3, 3, 2], parents=[0, 1], types=["spherical", "revolute"], noise_mm=0.3,
                 n_frames=120)


@st.composite
def damaged(draw):
    X = BASE.trial.as_array()
    F, M, _ = X.shape
    kind = draw(st.sampled_from(["gaps", "constant", "coincide", "short", "static", "blank", "huge"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    if kind == "gaps":                              # random holes, up to whole markers
        X[rng.random((F, M)) < draw(st.floats(0.0, 0.95))] = np.nan
    elif kind == "constant":                        # some markers frozen in the world
        for k in rng.choice(M, draw(st.integers(1, M)), replace=False):
            X[:, k] = X[0, k]
    elif kind == "coincide":                        # two labels for one marker
        a, b = rng.choice(M, 2, replace=False)
        X[:, b] = X[:, a]
    elif kind == "short":                           # a handful of frames
        X = X[:draw(st.integers(1, 12))]
    elif kind == "static":                          # nothing moves
        X = np.repeat(X[:1], F, axis=0) + rng.normal(0, 0.1, X.shape)
    elif kind == "blank":                           # frames without any marker
        X[rng.random(F) < 0.5] = np.nan
    else:                                           # the capture volume 500 m away
        X = X + 5e5
    return Trial(X, BASE.trial.labels, 100.0), kind


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])  # capsys: read first
@given(damaged())
def test_degenerate_trials_end_cleanly(tmp_path_factory, capsys, trial_kind):
    trial, kind = trial_kind
    d = tmp_path_factory.mktemp("fuzz")
    path = d / "t.trc"
    trial.to_file(path)
    capsys.readouterr()
    rc = cli.main(["skeleton", str(path), "--out", str(d / "m.toml"), "--json"])
    out = capsys.readouterr()
    assert rc in (0, 1, 2), (kind, out.err[-2000:])
    assert "Traceback" not in out.err and "internal error" not in out.err
    if rc == 2:
        assert "t.trc" in out.err and not out.out
