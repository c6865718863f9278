"""A hip seen through one thigh marker and a poorly excited motion: the per-frame noise stretches its standard
errors past the trigger, and its answer takes the bootstrap's sampling spread (never a narrower interval)."""
from __future__ import annotations

import warnings

import identcheck as ic
import identcheck.bundle.honest as honest
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

SPARSE_HIP = Model.from_dict({
    "units": "mm",
    "segments": {"pelvis": {"markers": ["LASI", "RASI", "SACR"]},
                 "thigh": {"markers": ["RTHI"], "length_mm": 420}},
    "joints": {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh"}}})


def _hip(trial):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ic.fit(SPARSE_HIP, trial).to_dict()["joints"]["hip"]


def test_a_hip_whose_poses_carry_the_noise_gets_its_sampling_spread(monkeypatch):
    """8° of motion, 1.5 mm noise: ``sampling_spread`` reports 20 draws and a ratio ≥ 1; every distance the bootstrap
    widened says so in its method and its interval holds the one computed without the bootstrap; the same fit with
    the trigger out of reach has no ``sampling_spread`` and no bootstrap method."""
    trial = simulate(SPARSE_HIP, n_frames=600, noise_mm=1.5, seed=1, rom_deg=8.0).trial
    hip = _hip(trial)
    assert hip["sampling_spread"]["draws"] == 20 and hip["sampling_spread"]["ratio"] >= 1.0
    widened = [m for m, how in hip["interval_method"].items() if "bootstrap" in how]
    assert widened
    monkeypatch.setattr(honest, "SPREAD_TRIGGER", float("inf"))
    plain = _hip(trial)
    assert "sampling_spread" not in plain
    assert not any("bootstrap" in how for how in plain["interval_method"].values())
    assert plain["marker_distances"] == hip["marker_distances"]
    for m in widened:
        lo, hi = hip["marker_distances_ci95"][m]
        plo, phi = plain["marker_distances_ci95"][m]
        assert lo <= plo and (hi is None or (phi is not None and hi >= phi))
        assert lo <= hip["marker_distances"][m] and (hi is None or hi >= hip["marker_distances"][m])
