"""A label swap the distances show without any joint model is an error in the data: ``diagnose`` corrects it before the
effects the joint model is asked to explain. Searched by score alone, skin terms with both of a thigh's joints' angles
absorbed part of a pelvis swap beside a shank delay and were adopted first; the swap was then never named (held-out
draw 33, trial 34). Here a swap of the two iliac-spine markers beside a 50 ms shank delay: the code before named the
delay first, then the swap, then an extra rotation and a thigh delay that the swap's frames had left behind."""
import warnings

import numpy as np

from identcheck.diagnose.workflow import diagnose
from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate

EXAMPLES = __import__("pathlib").Path(__file__).resolve().parents[2] / "examples"


def _swap_beside_delay(model, seed: int, lag: int, span: tuple):
    sim = simulate(model, n_frames=900, noise_mm=0.5, seed=seed)
    xyz = sim.trial.as_array().copy()
    for m in ("RTIB", "RTIB2", "RANK"):                  # the shank seen `lag` frames late
        c = sim.trial.index(m)
        xyz[lag:, c] = xyz[:-lag, c].copy()
        xyz[:lag, c] = np.nan
    i, j = sim.trial.index("LASI"), sim.trial.index("RASI")
    a, b = span
    xyz[a:b + 1, [i, j]] = xyz[a:b + 1, [j, i]]
    return sim.trial.replace(xyz=xyz)


def test_a_swap_is_corrected_before_the_delay_beside_it():
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    trial = _swap_beside_delay(model, 3, 5, (142, 227))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = diagnose(model, trial).to_dict()
    assert [e["name"] for e in rep["effects"]] == ["marker_swap", "time_offset"]
    first, second = rep["effects"]
    assert set(first["where"]["markers"]) == {"LASI", "RASI"} and first["where"]["frames"] == [142, 227]
    assert second["where"]["segment"] == "shank"
    assert rep["gap_after"] <= 1.5 * rep["noise_floor"]




def test_a_swap_is_adopted_though_the_corrected_data_leave_the_hip_less_determined(monkeypatch):
    """The hip turning about one axis, two pelvis markers swapped for 150 frames: posed on the swapped labels there,
    the rigid fit turns the pelvis about other axes too and the hip looks better determined than it is (worst standard
    error 0.23 mm; swapped back, 3.3 mm). The bar on the joints' standard errors (here scaled down, to 2 mm and
    twice the rigid fit's, so that this short simulated trial reaches it; held-out draw 48's sit-to-stand went from
    0.07 to 36 mm against 10 mm) does not keep out a correction that adds no parameter: the swap is named first."""
    import identcheck.diagnose.workflow as workflow
    from identcheck.effects.registry import EFFECTS

    monkeypatch.setattr(workflow, "MAX_SD_MM", 2.0)
    monkeypatch.setattr(workflow, "SD_GROWTH", 2.0)
    model = Model.from_toml(EXAMPLES / "diagnose_leg.toml")
    sim = simulate(model, n_frames=900, noise_mm=0.5, seed=0, n_axes=1)
    xyz = sim.trial.as_array().copy()
    i, j = sim.trial.index("LASI"), sim.trial.index("SACR")
    xyz[300:451, [i, j]] = xyz[300:451, [j, i]]
    trial = sim.trial.replace(xyz=xyz)
    ctx, h = workflow.start(model, trial)
    swap, skin = EFFECTS["marker_swap"], EFFECTS["soft_tissue"]
    prop = next(p for p in swap.propose(ctx, h) if set(p.where["markers"]) == {"LASI", "SACR"})
    cand = swap.apply(ctx, h, prop).polish()
    assert workflow.corrects_data_only(h, cand)
    assert not workflow.corrects_data_only(h, skin.apply(ctx, h, skin.propose(ctx, h)[0]))
    assert workflow.worst_sd(ctx, cand) > max(workflow.SD_GROWTH * workflow.worst_sd(ctx, h), workflow.MAX_SD_MM)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rep = diagnose(model, trial).to_dict()
    first = rep["effects"][0]
    assert first["name"] == "marker_swap" and set(first["where"]["markers"]) == {"LASI", "SACR"}
