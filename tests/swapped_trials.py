"""Diagnosing a simulated trial whose labels were exchanged, as a user would: written to a TRC file, read back, and
the first named effect checked to be the swap with its markers and span."""
import warnings

from identcheck.diagnose.workflow import diagnose
from identcheck.trial import Trial


def assert_swap_named_first(model, sim, xyz, tmp_path, markers: set, frames: list) -> None:
    """`sim`'s trial with positions `xyz`, written to a TRC in `tmp_path` and diagnosed: the first effect is the swap
    of `markers` over `frames`, and the gap left is within 1.5x the noise floor."""
    trc = tmp_path / "swapped.trc"
    sim.trial.replace(xyz=xyz).to_file(trc)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = diagnose(model, Trial.from_file(trc)).to_dict()
    first = rep["effects"][0]
    assert first["name"] == "marker_swap" and set(first["where"]["markers"]) == markers
    assert first["where"]["frames"] == frames
    assert rep["gap_after"] <= 1.5 * rep["noise_floor"]
