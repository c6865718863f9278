"""`diagnose` judges the joints of its final model once, and says so: the profiles and bootstrap refits of a weakly
determined joint can take minutes, and the JSON, the text and the HTML report all read that one answer."""
from __future__ import annotations

import json
from pathlib import Path

from identcheck import cli
import identcheck as ic
import identcheck.diagnose.workflow as workflow
from identcheck.report.text import diagnose_text

ROOT = Path(__file__).resolve().parents[2]
MODEL = str(ROOT / "examples" / "diagnose_leg.toml")


def _trial(tmp_path):
    trial = tmp_path / "slip.trc"
    assert cli.main(["simulate", MODEL, "--out", str(trial), "--seed", "5", "--noise-mm", "0.4", "--frames", "400",
                     "--effect", "marker_slip"]) == 0
    return trial


def test_the_joints_are_judged_once_whatever_reads_them(tmp_path, monkeypatch):
    calls = []
    real = workflow.assess

    def counted(*args, **kwargs):
        calls.append(kwargs.get("progress"))
        return real(*args, **kwargs)

    monkeypatch.setattr(workflow, "assess", counted)
    heard = []
    diag = ic.diagnose(MODEL, _trial(tmp_path), progress=heard.append)
    assert calls == []                                  # not judged before anything asks
    first = diag.to_dict()
    text = diagnose_text(diag)
    again = diag.to_dict()
    assert len(calls) == 1
    assert first["joints"] is again["joints"] is diag.joints
    assert set(first["joints"]) == set(diag.ctx.model.joints)
    assert all(name in text for name in first["joints"])
    assert any(line.startswith("judging the joints") for line in heard)


def test_the_cli_reports_the_judgment_on_stderr(tmp_path, capsys):
    trial = _trial(tmp_path)
    capsys.readouterr()
    cli.main(["diagnose", MODEL, str(trial), "--json", "--report", str(tmp_path / "page.html")])
    out = capsys.readouterr()
    assert "identcheck diagnose: judging the joints" in out.err
    assert out.err.count("judging the joints") == 1
    assert set(json.loads(out.out)["joints"]) == {"hip", "knee"}


def test_the_final_model_is_judged_converged_or_claims_nothing(tmp_path, monkeypatch):
    """The joints are judged on the final model taken to convergence by fit's rule (the last step's gap is that
    model's); a final model that cannot be converged within the budget claims no interval for any joint and says why,
    without a single profile refit (they had run a minute about a point that was no minimum)."""
    import identcheck.bundle.converge as converge
    import identcheck.bundle.honest as honest

    trial = _trial(tmp_path)
    diag = ic.diagnose(MODEL, trial)
    assert diag.after.fit.converged
    if diag.steps:
        assert diag.steps[-1].gap_after == diag.gap_after
    monkeypatch.setattr(converge, "MAX_ITER", 0)           # no iteration: the final model is not converged
    monkeypatch.setattr(converge, "CONVERGE_BUDGET_S", 0.0)
    monkeypatch.setattr(honest, "profile_interval", lambda *a, **k: (_ for _ in ()).throw(AssertionError("profiled")))
    stuck = ic.diagnose(MODEL, trial, max_steps=0)
    assert not stuck.after.fit.converged
    for answer in stuck.to_dict()["joints"].values():
        assert set(answer["interval_method"].values()) == {"unbounded"}
        assert all(hi is None for _, hi in answer["marker_distances_ci95"].values())
        assert not answer["unique"] and "did not converge" in answer["practical"]["reason"]


def test_skin_the_effects_fit_still_widens_the_joints_beside_it(tmp_path):
    """A marker wobbling 5-10 mm with its joint's angle: diagnose fits its skin motion, and the joints beside its
    segment keep the model error that motion gives in ``fit`` (their cluster may move with the angles as well,
    unseen); a joint the motion does not touch has none."""
    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate
    from identcheck.effects.registry import EFFECTS, inject_effect

    model = Model.from_toml(MODEL)
    sim = inject_effect(simulate(model, n_frames=600, noise_mm=0.4, seed=3), "soft_tissue", seed=3)
    trial = tmp_path / "skin.trc"
    sim.trial.to_trc(trial)
    diag = ic.diagnose(MODEL, trial)
    assert "soft_tissue" in [s.name for s in diag.steps]
    seg = sim.settings["effect"]["where"]["segment"]
    fitted = [p for p in diag.after.effects if p.effect in ("soft_tissue", "joint_translation")]
    assert fitted and all(EFFECTS[p.effect].modelled_motion(p, diag.after) for p in fitted)   # its terms are found
    report = diag.to_dict()
    for j, ans in report["joints"].items():
        beside = seg in (model.joints[j].parent, model.joints[j].child)
        assert ("model_error_sd_mm" in ans["practical"]) == beside, (j, seg, ans["practical"])
        if beside:
            assert ans["practical"]["model_error_sd_mm"] >= 1.5
            assert all("model_error" in how or how == "unbounded" for how in ans["interval_method"].values())


def test_a_moving_centre_the_effects_fit_leaves_its_own_joint_unclaimed(tmp_path):
    """A knee whose centre moves with its angle (8-15 mm): diagnose fits the translation and finds its terms in the
    final model. Where the centre is at any one pose is not identifiable (the motion's part linear in the angle is a
    shifted axis to the data): the knee is undetermined with no interval claimed, and its intervals to the centre's
    fitted place over the trial (``moving_centre``) carry at least 1.5 times the fitted motion as model error (more
    where the shank's cluster moving as one, which the data cannot tell from it, reads it as skin); the hip
    keeps its own answer. The terminal says so."""
    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate
    from identcheck.effects.registry import inject_effect
    from identcheck.diagnose.workflow import modelled_motion
    from identcheck.bundle.honest import MOVING_CENTRE_REASON

    model = Model.from_toml(MODEL)
    sim = inject_effect(simulate(model, n_frames=600, noise_mm=0.4, seed=2), "joint_translation", seed=2)
    assert sim.settings["effect"]["where"]["joint"] == "knee"
    trial = tmp_path / "moving.trc"
    sim.trial.to_trc(trial)
    diag = ic.diagnose(MODEL, trial)
    assert [s.name for s in diag.steps] == ["joint_translation"]
    motions = modelled_motion(diag.after)
    assert [m.joint for m in motions] == ["knee"] and motions[0].rms_mm > 1.0
    joints = diag.to_dict()["joints"]
    knee, hip = joints["knee"], joints["hip"]
    assert knee["practical"]["model_error_sd_mm"] >= round(1.5 * motions[0].rms_mm, 3) - 1e-3
    assert knee["practical"]["verdict"] == "undetermined" and not knee["unique"]
    assert MOVING_CENTRE_REASON in knee["practical"]["reason"] and knee["uncertainty_mm"] is None
    assert "model error" in knee["practical"]["reason"]            # what widens the intervals to its place is said
    assert all(iv == [0.0, None] for iv in knee["marker_distances_ci95"].values())
    assert set(knee["interval_method"].values()) == {"moving_centre"}
    functional = knee["moving_centre"]
    assert functional["motion_rms_mm"] == round(motions[0].rms_mm, 3)
    assert all("model_error" in how for how in functional["interval_method"].values())
    for m, d in knee["marker_distances"].items():
        lo, hi = functional["marker_distances_ci95"][m]
        assert lo <= d <= hi
    assert "model_error_sd_mm" not in hip["practical"] and "moving_centre" not in hip
    assert MOVING_CENTRE_REASON not in hip["practical"]["reason"]
    assert "knee: its centre moves with its angles" in diagnose_text(diag)
    from identcheck.report.html import joints_table                  # and the page, beside the unbounded intervals
    assert joints_table(joints).count("to its place over the trial") == len(knee["marker_distances"])
