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
