"""`fit` screens for swapped marker labels first (model-free within-segment distances): the swapped span
is left out for the two markers and named, clean trials pass untouched, and the input file is unchanged."""
import hashlib
import json

import numpy as np
import pytest

from identcheck import cli
from identcheck.effects.registry import inject_effect
from identcheck.estimate.labels import screen
from identcheck.io.model import Model
from identcheck.io.trc import write_trc
from identcheck.simulate.rigid import simulate

EXAMPLES = __import__("pathlib").Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("seed", [1, 4, 9])
def test_a_hidden_swap_is_named_and_left_out(seed):
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = inject_effect(simulate(model, n_frames=300, noise_mm=0.5, seed=seed), "marker_swap", seed)
    where = sim.settings["effect"]["where"]
    screened, warnings = screen(model, sim.trial)
    assert len(warnings) == 1 and all(m in warnings[0]["message"] for m in where["markers"])
    assert sorted(warnings[0]["markers"]) == sorted(where["markers"]) and warnings[0]["kind"] == "label_swap"
    a, b = where["frames"]
    assert f"frames {a}-{b}" in warnings[0]["message"] or _overlap(warnings[0]["frames"], a, b) > 0.9
    cols = [screened.labels.index(m) for m in where["markers"]]
    out = screened.as_array()[:, cols]
    assert np.isnan(out[a:b + 1]).all()                           # the span is out for both markers
    kept = np.ones(sim.trial.n_frames, bool); kept[a:b + 1] = False
    np.testing.assert_array_equal(out[kept], sim.trial.as_array()[kept][:, cols])
    assert np.isfinite(sim.trial.as_array()[a:b + 1][:, cols]).all()   # the caller's trial is not modified


def _overlap(frames, a, b):
    lo, hi = frames
    return max(0, min(b, hi) - max(a, lo) + 1) / (b - a + 1)


def test_clean_trials_pass_untouched():
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    for seed in range(3):
        sim = simulate(model, n_frames=300, noise_mm=0.5, seed=seed, occlusion=0.3)
        screened, warnings = screen(model, sim.trial)
        assert warnings == [] and screened is sim.trial


def test_cli_fit_warns_and_reports_in_json(tmp_path, capsys):
    model_path = EXAMPLES / "diagnose_leg.toml"
    sim = inject_effect(simulate(Model.from_toml(model_path), n_frames=300, noise_mm=0.5, seed=4), "marker_swap", 4)
    trc = tmp_path / "swapped.trc"
    write_trc(trc, sim.trial.as_array(), sim.trial.labels, sim.trial.rate_hz)
    before = hashlib.sha256(trc.read_bytes()).hexdigest()
    cli.main(["fit", str(model_path), str(trc), "--json"])
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    swaps = [w for w in doc["warnings"] if w["kind"] == "label_swap"]
    assert len(swaps) == 1 and "look swapped" in cap.err and "swapped.trc" in swaps[0]["message"]
    assert hashlib.sha256(trc.read_bytes()).hexdigest() == before


def test_a_gap_edge_artefact_is_not_a_swap():
    """A marker that comes back from a gap 25 mm off and settles over a few frames (a bad gap fill) fits
    'better exchanged' only by accident, not well: no swap is reported."""
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=300, noise_mm=0.3, seed=5)
    xyz = sim.trial.as_array()
    c = sim.trial.labels.index("RTHI")
    xyz[100:110, c] = np.nan
    ramp = np.linspace(25.0, 0.0, 8)[:, None] * np.array([1.0, 0.0, 0.0])
    xyz[110:118, c] += ramp
    from identcheck.trial import Trial

    trial = Trial(xyz, sim.trial.labels, sim.trial.rate_hz, "artefact")
    screened, warnings = screen(model, trial)
    assert warnings == [] and screened is trial
