"""The CLI end to end: the README's main job, contract exit codes, clear errors."""
import json
import os
from pathlib import Path

import numpy as np
import pytest


from identcheck import cli
from identcheck.simulate.rigid import load_truth

ROOT = Path(__file__).resolve().parents[2]
KNEE = str(ROOT / "examples" / "knee_21.toml")


def test_main_job_finds_the_true_knee_among_four_joints(tmp_path, capsys):
    trial, truth = tmp_path / "knee.c3d", tmp_path / "truth.json"
    assert cli.main(["simulate", KNEE, "--out", str(trial), "--truth", str(truth)]) == 0
    capsys.readouterr()
    assert cli.main(["identify", KNEE, str(trial), "--json"]) == 1  # not unique: exit 1 (negative answer)
    out = json.loads(capsys.readouterr().out)["joints"]["knee_r"]
    assert out["candidates"] == 4 and out["parameter_sets"] == 2 and out["unique"] is False
    true = load_truth(truth).marker_distances("knee_r")
    sets = [out["marker_distances"]] + [a["marker_distances"] for a in out["alternatives"]]
    best = min(max(abs(s[m] - true[m]) for m in true) for s in sets)
    assert best < 0.5  # mm; C3D stores float32
    worst = max(max(abs(s[m] - true[m]) for m in true) for s in sets)
    assert worst > 1.0  # the twin joint of erratum E1 really differs


def test_identify_on_trc_matches_truth(tmp_path, capsys):
    trial, truth = tmp_path / "knee.trc", tmp_path / "truth.json"
    assert cli.main(["simulate", KNEE, "--out", str(trial), "--truth", str(truth), "--seed", "3"]) == 0
    capsys.readouterr()
    cli.main(["identify", KNEE, str(trial), "--json"])
    out = json.loads(capsys.readouterr().out)["joints"]["knee_r"]
    true = load_truth(truth).marker_distances("knee_r")
    sets = [out["marker_distances"]] + [a["marker_distances"] for a in out["alternatives"]]
    assert min(max(abs(s[m] - true[m]) for m in true) for s in sets) < 0.5


def test_identify_rejects_cases_it_does_not_cover(tmp_path, capsys):
    leg = str(ROOT / "examples" / "leg.toml")
    trial = tmp_path / "leg.trc"
    assert cli.main(["simulate", leg, "--out", str(trial)]) == 0
    assert cli.main(["identify", leg, str(trial), "--joint", "knee_r"]) == 2  # revolute (3,2): not an exact case
    assert "revolute (2,1)" in capsys.readouterr().err
    assert cli.main(["identify", leg, str(trial), "--joint", "nope"]) == 2
    assert "unknown joint 'nope'" in capsys.readouterr().err


def test_identify_spherical_cases_match_truth(tmp_path, capsys):
    """Both exact spherical cases of Pham et al. recover the simulated hip, uniquely."""
    for name, case_ in (("hip_31", "spherical(3,1)"), ("hip_22", "spherical(2,2)")):
        model = str(ROOT / "examples" / f"{name}.toml")
        trial, truth = tmp_path / f"{name}.c3d", tmp_path / f"{name}.json"
        assert cli.main(["simulate", model, "--out", str(trial), "--truth", str(truth), "--seed", "5"]) == 0
        capsys.readouterr()
        assert cli.main(["identify", model, str(trial), "--json"]) == 0  # unique: exit 0
        out = json.loads(capsys.readouterr().out)["joints"]["hip_r"]
        assert out["case"] == case_ and out["unique"] and out["candidates"] == 1
        true = load_truth(truth).marker_distances("hip_r")
        assert max(abs(out["marker_distances"][m] - true[m]) for m in out["marker_distances"]) < 0.05  # float32


def test_identify_noisy_trial_is_a_clear_answer_not_a_traceback(tmp_path, capsys):
    trial = tmp_path / "noisy.c3d"
    assert cli.main(["simulate", KNEE, "--out", str(trial), "--noise-mm", "2"]) == 0
    code = cli.main(["identify", KNEE, str(trial)])
    err = capsys.readouterr().err
    assert code in (0, 1)
    if err:
        assert "identcheck identify" in err and "Traceback" not in err


def test_every_contract_verb_is_built(capsys):
    for verb in ("table", "rank", "identify", "simulate", "fit", "plan", "diagnose"):
        assert cli.main([verb, "--help"]) == 0
        out = capsys.readouterr().out
        assert out.startswith(f"usage: identcheck {verb}") and "not available yet" not in out


def test_simulate_bad_extension_and_effect(tmp_path, capsys):
    assert cli.main(["simulate", KNEE, "--out", str(tmp_path / "x.csv")]) == 2
    assert "x.csv" in capsys.readouterr().err
    assert cli.main(["simulate", KNEE, "--out", str(tmp_path / "x.trc"), "--effect", "wobble"]) == 2
    assert "invalid choice: 'wobble'" in capsys.readouterr().err
    assert not (tmp_path / "x.trc").exists()
    assert cli.main(["simulate", KNEE, "--out", str(tmp_path / "x.trc"), "--effect", "marker_slip"]) == 0
    assert (tmp_path / "x.trc").exists()


@pytest.mark.parametrize("ext", [".trc", ".c3d"])
def test_simulate_refuses_a_model_without_markers_and_writes_nothing(tmp_path, capsys, ext):
    """A model whose segments list no markers had been simulated into a file of frames alone, which no reader (the
    TRC reader of this package included) takes."""
    model = tmp_path / "bare.toml"
    model.write_text('[segments.pelvis]\nmarkers = []\n[segments.thigh]\nmarkers = []\n'
                     '[joints.hip]\ntype = "spherical"\nparent = "pelvis"\nchild = "thigh"\n')
    assert cli.main(["simulate", str(model), "--out", str(tmp_path / f"x{ext}")]) == 2
    err = capsys.readouterr().err
    assert "bare.toml" in err and "no markers" in err
    assert not (tmp_path / f"x{ext}").exists()


def test_flexion_only_hip_is_named_coplanar_with_the_motion_to_add(tmp_path, capsys):
    model = str(ROOT / "examples" / "hip_31.toml")
    exact, noisy = tmp_path / "flex.trc", tmp_path / "flex_noisy.trc"
    assert cli.main(["simulate", model, "--out", str(exact), "--n-axes", "1"]) == 0
    assert cli.main(["simulate", model, "--out", str(noisy), "--n-axes", "1", "--noise-mm", "0.5"]) == 0
    capsys.readouterr()
    assert cli.main(["identify", model, str(exact)]) == 1
    err = capsys.readouterr().err
    assert "coplanar" in err and "not identifiable" in err and "Traceback" not in err
    assert cli.main(["identify", model, str(noisy)]) == 0
    err = capsys.readouterr().err
    assert "warning: the samples are nearly coplanar" in err and "abduction" in err


def test_internal_error_is_exit_3_with_a_request_to_report(monkeypatch, capsys):
    from identcheck import api

    def broken(*args, **kwargs):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(api, "table", broken)
    assert cli.main(["table"]) == 3
    err = capsys.readouterr().err
    assert "ZeroDivisionError: a bug" in err and "internal error" in err and "report" in err


@pytest.mark.parametrize("verb, argv", [("table", ["table"]), ("plan", ["plan", "examples/body16.toml"])])
def test_ctrl_c_is_one_line_and_exit_130_not_a_traceback(monkeypatch, capsys, verb, argv):
    """A verb stopped by Ctrl-C had printed Python's whole traceback ending in KeyboardInterrupt: it now says it was
    interrupted, in one line, and exits 130 (the shell's code for a program stopped by SIGINT)."""
    from identcheck import api

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(api, verb, stopped)
    assert cli.main([a if not a.endswith(".toml") else str(ROOT / a) for a in argv]) == 130
    err = capsys.readouterr().err
    assert err.strip() == f"identcheck {verb}: interrupted" and "Traceback" not in err


def test_a_full_standard_output_is_named_not_the_input_files():
    """Writing the answer to a full device is exit 2 naming standard output (it had named the model and trial)."""
    import subprocess
    import sys

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system")
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "identcheck", "rank", "revolute", "2", "1", "--json"], stdout=full,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    assert done.returncode == 2
    assert "identcheck rank: standard output: No space left on device" in done.stderr
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr


def test_a_closed_standard_output_is_refused_before_any_work():
    """Started with standard output closed, Python drops every print: the command had run and exited 0 with its
    answer lost. It is refused, exit 2, saying so."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "identcheck", "rank", "revolute", "2", "1"],
                          preexec_fn=lambda: os.close(1), stderr=subprocess.PIPE, text=True, timeout=120)
    assert done.returncode == 2
    assert "standard output is closed" in done.stderr and "revolute (2,1)" not in done.stderr


def test_version_and_no_blas_variables_set_on_import():
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", "import os, identcheck.cli; print(os.environ.get('OMP_NUM_THREADS'))"],
                         env=env, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "None"
    assert cli.main(["--version"]) == 0


def test_a_model_marker_never_visible_is_named_not_dropped(tmp_path, capsys):
    """A marker of the model whose every sample is empty: fit and diagnose exit 2 naming the marker, its
    segment and the file (before, fit dropped it and advised adding markers to a segment that has it)."""
    from identcheck.io.trc import read_trc, write_trc

    leg = str(ROOT / "examples" / "leg.toml")
    trial = tmp_path / "leg.trc"
    assert cli.main(["simulate", leg, "--out", str(trial), "--seed", "2"]) == 0
    capsys.readouterr()
    md = read_trc(trial)
    xyz = md.xyz.copy()
    xyz[:, list(md.labels).index("RTHI")] = np.nan
    blind = tmp_path / "blind.trc"
    write_trc(blind, xyz, md.labels, md.rate_hz)
    before = blind.read_bytes()
    for verb in ("fit", "diagnose"):
        assert cli.main([verb, leg, str(blind), "--json"]) == 2
        err = capsys.readouterr().err
        assert "'RTHI'" in err and "thigh_r" in err and "never visible" in err and "blind.trc" in err, err
    assert blind.read_bytes() == before


def test_bad_outputs_and_arguments_are_refused_before_any_work(tmp_path, capsys, monkeypatch):
    """Output paths that are a directory, under a missing directory or a file where a directory belongs,
    swapped arguments and out-of-range numbers: exit 2 at once, naming the option and the path (before,
    tracebacks after the work, with the JSON lost). Nothing is created."""
    import identcheck.api as api_mod

    def no_work(*args, **kwargs):
        raise AssertionError("the work started")

    for verb in ("rank", "table", "simulate", "plan", "derive", "diagnose", "fit", "identify"):
        monkeypatch.setattr(api_mod, verb, no_work)
    a_file = tmp_path / "a_file.txt"
    a_file.write_text("x")
    model = str(ROOT / "examples" / "leg.toml")
    cases = [
        (["rank", "revolute", "2", "1", "--save", str(tmp_path)], "--save", "is a directory"),
        (["table", "--save", str(tmp_path / "missing" / "t.json")], "--save", "does not exist"),
        (["simulate", model, "--out", str(tmp_path / "nope" / "x.trc")], "--out", "does not exist"),
        (["plan", model, "--figure", str(tmp_path)], "--figure", "is a directory"),
        (["derive", "--out", str(a_file)], "--out", "is a file"),
        (["diagnose", model, "t.trc", "--plots", str(a_file / "sub")], "--plots", "is a file"),
        (["fit", "trial.c3d", model], "swapped", "identcheck fit"),
        (["rank", "revolute", "2", "1", "--samples", "1000000000"], "--samples", "between"),
        (["identify", model, "t.trc", "--precision", "-3"], "--precision", "between"),
        (["identify", model, "t.trc", "--frames", "a,b"], "--frames", "indices"),
        (["simulate", model, "--out", str(tmp_path / "x.trc"), "--rate", "0"], "--rate", "out of range"),
    ]
    for argv, option, reason in cases:
        assert cli.main(argv) == 2, argv
        err = capsys.readouterr().err
        assert option in err and reason in err, (argv, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file.txt"]


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc, where no file can be created")
def test_outputs_where_no_file_can_be_created_are_refused_before_any_work(tmp_path, capsys, monkeypatch):
    """A folder whose permission bits allow writing but where no file can be created (/proc; a read-only mount):
    exit 2 before the work, naming the option and the folder, and none of the command's other outputs written
    (before, each verb computed, then failed naming its temporary file, and `simulate --out A --truth /proc/t.json`
    left A behind)."""
    import identcheck.api as api_mod

    def no_work(*args, **kwargs):
        raise AssertionError("the work started")

    for verb in ("table", "simulate", "plan", "diagnose", "fit", "skeleton"):
        monkeypatch.setattr(api_mod, verb, no_work)
    model = str(ROOT / "examples" / "leg.toml")
    kept = tmp_path / "x.trc"
    cases = [(["fit", model, "t.trc", "--export-markers", "/proc/x.trc"], "--export-markers"),
             (["fit", model, "t.trc", "--report", "/proc/x.html"], "--report"),
             (["table", "--save", "/proc/x.json"], "--save"),
             (["plan", model, "--figure", "/proc/x.png"], "--figure"),
             (["skeleton", "t.trc", "--out", "/proc/x.toml"], "--out"),
             (["simulate", model, "--out", str(kept), "--truth", "/proc/t.json"], "--truth"),
             (["diagnose", model, "t.trc", "--plots", "/proc/plots"], "--plots")]
    for argv, option in cases:
        assert cli.main(argv) == 2, argv
        err = capsys.readouterr().err
        # (as root, by the probe; as another user, by the folder's permission bits)
        assert option in err and "/proc" in err and ("cannot create" in err or "not writable" in err), (argv, err)
        assert ".tmp-" not in err, (argv, err)
    assert not any(tmp_path.iterdir())


def test_a_write_that_fails_late_names_the_file_asked_for(tmp_path, monkeypatch):
    """Should writing fail after the checks (a full disk, a folder removed meanwhile), the error names the file the
    user asked for, not the temporary name it was being written under."""
    from identcheck.io import atomic

    target = tmp_path / "gone" / "result.json"
    with pytest.raises(OSError) as info:
        atomic.atomic_write(target, "{}")
    assert info.value.filename == str(target) and ".tmp-" not in str(info.value)
    link = tmp_path / "link.json"                 # a symbolic link is named as given, not by where it leads
    link.symlink_to(tmp_path / "gone" / "target.json")
    with pytest.raises(OSError) as info:
        atomic.atomic_write(link, "{}")
    assert info.value.filename == str(link), info.value


def test_fit_exports_the_joints_as_virtual_markers_in_the_files_numbering(tmp_path, capsys):
    """fit --frames 50:250 --export-markers OUT: the file holds every measured marker plus hip_r.centre and
    each hinge's axis0/axis1, numbered from frame 50 as the input; the exported centre follows the
    simulator's true centre within 2.5 mm and the hinge direction within 2 degrees in every frame."""
    from identcheck.simulate.rigid import load_truth
    import identcheck as ic

    leg = str(ROOT / "examples" / "leg.toml")
    trial, truth = tmp_path / "leg.trc", tmp_path / "truth.json"
    assert cli.main(["simulate", leg, "--out", str(trial), "--truth", str(truth), "--seed", "4", "--noise-mm", "0.5",
                     "--frames", "300"]) == 0
    out = tmp_path / "with_joints.trc"
    assert cli.main(["fit", leg, str(trial), "--frames", "50:250", "--export-markers", str(out), "--json"]) == 0
    capsys.readouterr()
    t = ic.read_trial(out)
    assert t.first_frame == 50 and t.n_frames == 201
    assert {"hip_r.centre", "knee_r.axis0", "knee_r.axis1", "ankle_r.axis0", "ankle_r.axis1"} <= set(t.labels)
    tr = load_truth(truth)
    rows = slice(49, 250)                       # TRC frame f is row f - 1
    err = np.linalg.norm(t.marker("hip_r.centre") - tr.centre_world("hip_r")[rows], axis=1)
    assert np.nanmax(err) < 2.5
    d = (t.marker("knee_r.axis1") - t.marker("knee_r.axis0")) / 100.0
    cos = np.abs(np.sum(d * tr.axis_world("knee_r")[rows], axis=1))
    assert np.degrees(np.arccos(np.clip(np.nanmin(cos), 0, 1))) < 2.0
    assert cli.main(["fit", leg, str(out)]) == 2      # its markers carry the joints' names: refused, named
    err = capsys.readouterr().err
    assert "'hip_r.centre'" in err and "virtual marker" in err


def test_diagnose_exports_the_joints_where_the_file_has_them(tmp_path, capsys):
    """diagnose --export-markers OUT on a trial 100 m from the origin (diagnose fits it moved near the origin):
    the exported hip centre follows the simulator's true centre within 2.5 mm in the file's coordinates."""
    from identcheck.simulate.rigid import load_truth
    from identcheck.io.trc import write_trc
    import identcheck as ic

    model = str(ROOT / "examples" / "diagnose_leg.toml")
    trial, truth = tmp_path / "leg.trc", tmp_path / "truth.json"
    assert cli.main(["simulate", model, "--out", str(trial), "--truth", str(truth), "--seed", "5", "--noise-mm",
                     "0.5", "--frames", "300"]) == 0
    t = ic.read_trial(trial)
    far = tmp_path / "far.trc"
    write_trc(far, t.as_array() + 100_000.0, t.labels, t.rate_hz)
    out = tmp_path / "with_joints.c3d"
    assert cli.main(["diagnose", model, str(far), "--export-markers", str(out), "--json"]) in (0, 1)
    capsys.readouterr()
    got = ic.read_trial(out)
    tr = load_truth(truth)
    joint = next(j for j in tr.joints if f"{j}.centre" in got.labels)
    err = np.linalg.norm(got.marker(f"{joint}.centre") - (tr.centre_world(joint) + 100_000.0), axis=1)
    assert np.nanmax(err) < 2.5


def test_identify_names_the_marker_occluded_in_a_frame_asked_for(tmp_path, capsys):
    """`identify --frames` with frames where a marker is hidden names that marker in each such frame (it had said only
    "a marker of [the joint's four] is occluded there")."""
    from identcheck import api
    from identcheck.io.trc import read_trc, write_trc

    model = str(ROOT / "examples" / "hip_31.toml")
    api.simulate(model, tmp_path / "hip.trc", seed=1, n_frames=40)
    trial = read_trc(tmp_path / "hip.trc")
    xyz = trial.xyz.copy()
    xyz[[3, 4], list(trial.labels).index("LPELVIS")] = np.nan
    write_trc(tmp_path / "hidden.trc", xyz, trial.labels, trial.rate_hz)
    assert cli.main(["identify", model, str(tmp_path / "hidden.trc"), "--frames", "2,3,4"]) == 2
    err = capsys.readouterr().err
    assert "frame 3: 'LPELVIS' occluded there" in err and "frame 4: 'LPELVIS' occluded there" in err, err
    assert "frame 2:" not in err and "'L5' occluded" not in err, err


@pytest.mark.parametrize("argv", [["fit", "m.toml", "t.trc", "--json"], ["diagnose", "m.toml", "t.trc"],
                                  ["plan", "m.toml"], ["skeleton", "t.trc", "--out", "m.toml"], ["table"]])
def test_verbose_is_taken_before_or_after_the_verb(argv):
    """``-v`` before the verb, after it, or not at all: the verb's own arguments parse alike, and only the flag
    differs; after the verb it had been refused with the top-level usage line."""
    from identcheck.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["-v"] + argv).verbose and parser.parse_args(argv + ["-v"]).verbose
    assert parser.parse_args(argv + ["--verbose"]).verbose and not parser.parse_args(argv).verbose
