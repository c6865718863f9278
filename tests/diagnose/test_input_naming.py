"""What ``diagnose`` refuses names the trial file it came from, as ``fit``'s refusals do: a closed-form start that
cannot be made from the trial's frames had been reported against ``<array>``."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from identcheck import api
from identcheck.errors import InputError
from identcheck.io.trc import read_trc, write_trc

ROOT = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("verb", ["fit", "diagnose"])
def test_a_trial_whose_frames_never_show_two_segments_whole_is_refused_naming_its_file(tmp_path, verb):
    """Every marker of the bundled leg seen in every other frame only, alternately: no frame shows a joint's two
    segments whole, so no closed form can start; both verbs refuse naming the file."""
    good, bad = tmp_path / "leg.trc", tmp_path / "alternating.trc"
    api.simulate(ROOT / "leg.toml", good, seed=2, n_frames=60)
    trial = read_trc(good)
    xyz = trial.xyz.copy()
    for m in range(xyz.shape[1]):
        xyz[(np.arange(len(xyz)) + m) % 2 == 0, m] = np.nan
    write_trc(bad, xyz, trial.labels, trial.rate_hz)
    with pytest.raises(InputError) as info:
        getattr(api, verb)(ROOT / "leg.toml", bad)
    assert "alternating.trc" in str(info.value) and "<array>" not in str(info.value), str(info.value)


def test_diagnose_keeps_what_it_warned_in_its_json_whatever_the_filters_and_on_degenerate_data(tmp_path, capsys):
    """The subject prefix taken off a trial's labels is a warning of kind ``subject_prefix`` in diagnose's JSON, as
    in fit's, under warnings ignored too (a batch run's filters had emptied diagnose's list); a static trial's
    degenerate answer (exit 1) carries the warnings said before it stopped."""
    import json
    import warnings

    from identcheck import cli
    from identcheck.trial import Trial

    src = tmp_path / "leg.trc"
    api.simulate(ROOT / "leg.toml", src, seed=1, n_frames=120, noise_mm=0.5)
    trial = Trial.from_file(src)
    prefixed = tmp_path / "subject.trc"
    Trial(trial.as_array(), ["Subj:" + lab for lab in trial.labels], trial.rate_hz).to_file(prefixed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        kinds = [w["kind"] for w in api.diagnose(ROOT / "leg.toml", prefixed).to_dict()["warnings"]]
    assert "subject_prefix" in kinds
    still = tmp_path / "still.trc"
    xyz = np.repeat(trial.as_array()[:1], 120, axis=0) + np.random.default_rng(0).normal(0.0, 0.5, (120, 10, 3))
    Trial(xyz, ["Subj:" + lab for lab in trial.labels], trial.rate_hz).to_file(still)
    capsys.readouterr()
    assert cli.main(["diagnose", str(ROOT / "leg.toml"), str(still), "--json"]) == 1
    doc = json.loads(capsys.readouterr().out)
    assert "degenerate" in doc and "subject_prefix" in [w["kind"] for w in doc["warnings"]], doc


@pytest.mark.parametrize("verb", ["fit", "diagnose"])
def test_a_trial_frozen_in_one_pose_is_degenerate_data_to_both_verbs(tmp_path, capsys, verb):
    """Every frame the same pose (a frozen export): both verbs answer degenerate data, exit 1 (diagnose had refused
    it as bad input, exit 2, calling it a noise-free trial), diagnose naming the file and saying why."""
    from identcheck import cli

    src = tmp_path / "leg.trc"
    api.simulate(ROOT / "leg.toml", src, seed=4, n_frames=80, noise_mm=0.5)
    trial = read_trc(src)
    frozen = tmp_path / "frozen.trc"
    write_trc(frozen, np.repeat(trial.xyz[:1], 80, axis=0), trial.labels, trial.rate_hz)
    capsys.readouterr()
    assert cli.main([verb, str(ROOT / "leg.toml"), str(frozen)]) == 1
    err = capsys.readouterr().err
    assert verb == "fit" or ("frozen.trc" in err and "every frame is the same" in err), err
