"""identcheck.batch.inputs: paths, globs, folders and manifests resolve to jobs, each trial once; settings hashes
change exactly when the settings do; every bad argument is named before any work."""
import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import given, strategies as st

from identcheck.batch import inputs
from identcheck.batch.inputs import fit_settings, plan_settings, resolve, settings_hash
from identcheck.errors import InputError

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "examples" / "diagnose_leg.toml"

NAMES = st.text(st.sampled_from("abcXYZ019_-"), min_size=1, max_size=6)
FILES = st.lists(st.tuples(st.sampled_from(["", "s1", "s1/deep", "s2", ".hidden"]), NAMES,
                           st.sampled_from([".trc", ".c3d", ".TRC", ".txt", ".json"])),
                 min_size=1, max_size=12, unique_by=lambda f: (f[0], f[1].lower(), f[2].lower()))


def _make(root: Path, files) -> list:
    """Create the files (empty: resolution never reads them); the trial files a folder scan must find."""
    made = []
    for sub, stem, ext in files:
        p = root / sub / f"{stem}{ext}"
        if p.exists():
            continue
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"")
        if ext.lower() in (".trc", ".c3d") and not sub.startswith("."):
            made.append(p)
    return made


@given(FILES, st.lists(st.sampled_from(["folder", "glob", "files", "subfolder"]), min_size=1, max_size=4))
def test_every_trial_is_found_exactly_once(files, ways):
    """However the trials are named (the folder, a recursive glob, each file, a subfolder; overlapping), each
    trial file is one job, hidden folders and other extensions are left out, and the order is stable."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "trials"
        root.mkdir()
        trials = _make(root, files)
        if not trials:
            return
        specs, expected = [], set()
        for way in ways:
            if way == "folder":
                specs.append(str(root))
                expected |= set(trials)
            elif way == "glob":                        # glob is case-sensitive here: one pattern per extension
                for ext in (".trc", ".c3d", ".TRC"):
                    matching = {t for t in trials if t.suffix == ext}
                    if matching:
                        specs.append(str(root / "**" / f"*{ext}"))
                        expected |= matching
            elif way == "files":
                specs += [str(t) for t in trials]
                expected |= set(trials)
            else:
                below = {t for t in trials if t.is_relative_to(root / "s1")}
                if below:
                    specs.append(str(root / "s1"))
                    expected |= below
        if not specs:
            return
        jobs = resolve("fit", [str(MODEL)] + specs)
        found = [Path(j.trial) for j in jobs]
        assert len(found) == len(set(found)) and set(found) == expected
        assert len({j.name for j in jobs}) == len(jobs)
        assert [j.name for j in resolve("fit", [str(MODEL)] + specs)] == [j.name for j in jobs]


PLAN_ARGS = st.tuples(st.integers(0, 3), st.booleans(), st.one_of(st.none(), st.sampled_from([0.5, 1, 1.0, 2])),
                      st.one_of(st.none(), st.sampled_from(["functional", "flexion"])),
                      st.one_of(st.none(), st.sampled_from([200, 1000])))


@given(PLAN_ARGS, PLAN_ARGS)
def test_plan_settings_hash_changes_iff_the_settings_do(a, b):
    sa, sb = plan_settings(*a), plan_settings(*b)
    assert (settings_hash(sa) == settings_hash(sb)) == (sa == sb)
    seed, fast, noise, motion, frames = a
    if noise is None:   # without a noise level the motion and its frames are not used: no re-run for them
        assert settings_hash(sa) == settings_hash(plan_settings(seed, fast, None, "small", 50))
    else:
        assert settings_hash(sa) != settings_hash(plan_settings(seed, fast, noise + 0.25, motion, frames))


@given(st.sampled_from(["fit", "diagnose"]), st.sampled_from(["fit", "diagnose"]),
       st.sampled_from([None, "", "1:100", "1:100 ", ":50", "10:"]), st.sampled_from([None, "1:100", ":50"]))
def test_fit_settings_hash_changes_iff_the_settings_do(va, vb, fa, fb):
    sa, sb = fit_settings(va, fa), fit_settings(vb, fb)
    assert (settings_hash(sa) == settings_hash(sb)) == (sa == sb)
    assert (sa == sb) == (va == vb and (fa or "").strip() == (fb or "").strip())


def test_manifest_paths_are_relative_to_it_and_rows_keep_their_frames(tmp_path, monkeypatch):
    data = tmp_path / "data"
    (data / "s1").mkdir(parents=True)
    for name in ("s1/a.trc", "b.c3d"):
        (data / name).write_bytes(b"")
    (data / "leg.toml").write_bytes(MODEL.read_bytes())
    (data / "trials.csv").write_text("trial,model,frames\n# a comment line\ns1/a.trc,leg.toml,1:100\n\n"
                                     "b.c3d,leg.toml,\ns1/a.trc,leg.toml,\n")
    monkeypatch.chdir(tmp_path)                          # the CSV's paths do not depend on the working folder
    jobs = resolve("diagnose", ["data/trials.csv"], frames="5:")
    assert [(Path(j.trial).name, j.settings["frames"]) for j in jobs] == [("a.trc", "1:100"), ("b.c3d", "5:"),
                                                                          ("a.trc", "5:")]
    assert all(Path(j.model) == data / "leg.toml" and os.path.isabs(j.trial) for j in jobs)
    assert jobs[0].name == "a.trc--leg--frames1-100.diagnose" and len({j.name for j in jobs}) == 3


def test_manifest_problems_name_the_file_and_line(tmp_path):
    (tmp_path / "a.trc").write_bytes(b"")
    (tmp_path / "m.toml").write_bytes(MODEL.read_bytes())
    csv = tmp_path / "runs.csv"
    csv.write_text("trial,model,frames\na.trc,,\n,m.toml,\nnope.trc,m.toml,\na.trc,m.toml,x\na.trc,a.trc,\n")
    with pytest.raises(InputError) as exc:
        resolve("fit", [str(csv)])
    msg = str(exc.value)
    for line, what in ((2, "no model"), (3, "no trial"), (4, "trial nope.trc: no such file"),
                       (5, "frames 'x': expected START:END"), (6, "model a.trc: not a model file")):
        assert f"{csv}, line {line}: {what}" in msg, (line, msg)
    csv.write_text("trial,modle\na.trc,m.toml\n")
    with pytest.raises(InputError, match=r"line 1: the header must name the columns trial,model\[,frames\]"):
        resolve("fit", [str(csv)])


def test_arguments_are_checked_before_any_work(tmp_path):
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "a.trc").write_bytes(b"")
    (tmp_path / "empty").mkdir()
    cases = {
        (str(tmp_path / "t"),): "trials without a model",
        (str(MODEL), str(MODEL.with_name("leg.toml")), str(tmp_path / "t")): "one model for the trials",
        (str(MODEL), str(tmp_path / "nothere")): "nothere: no such file or folder",
        (str(MODEL), str(tmp_path / "*.c3d")): "no trial file (.trc, .c3d) matches",
        (str(MODEL), str(tmp_path / "empty")): "a folder without trial files",
        (str(tmp_path / "missing.toml"), str(tmp_path / "t")): "missing.toml: no such file",
    }
    for args, msg in cases.items():
        with pytest.raises(InputError, match=msg.replace("(", r"\(").replace(")", r"\)").replace(".", r"\.")):
            resolve("fit", list(args))
    with pytest.raises(InputError, match="the model is given twice"):
        resolve("fit", [str(MODEL), str(tmp_path / "t")], model=MODEL)
    with pytest.raises(InputError, match="--frames '1-5'"):
        resolve("fit", [str(tmp_path / "t")], model=MODEL, frames="1-5")
    with pytest.raises(InputError, match="batch verb 'identify'"):
        resolve("identify", [str(MODEL)])
    assert not any(p.name == "out" for p in tmp_path.iterdir())


def test_plan_sweeps_models_x_noise_x_motion(tmp_path):
    models = [str(MODEL), str(ROOT / "examples" / "hip_31.toml")]
    jobs = resolve("plan", models, noise_mm="0.5, 1,0.5", motion=["functional", "flexion"], frames=200, fast=True)
    assert len(jobs) == 2 * 2 * 2
    assert jobs[0].name == "diagnose_leg--noise0.5mm--functional.plan"
    assert {(j.settings["noise_mm"], j.settings["motion"]) for j in jobs} == {
        (0.5, "functional"), (0.5, "flexion"), (1.0, "functional"), (1.0, "flexion")}
    assert all(j.trial is None and j.settings["frames"] == 200 and j.settings["fast"] for j in jobs)
    plain = resolve("plan", [str(ROOT / "examples")])          # a folder of models, no sweep: one job per model
    assert len(plain) == len(list((ROOT / "examples").rglob("*.toml"))) and plain[0].settings["noise_mm"] is None
    for kw, msg in (({"noise_mm": "0,-1"}, "--noise-mm 0: a positive"), ({"motion": "flexion"}, "--motion applies"),
                    ({"noise_mm": 1, "motion": "jogging"}, "--motion jogging: one of functional")):
        with pytest.raises(InputError, match=msg):
            resolve("plan", models, **kw)


def test_a_recorded_motion_is_an_input_of_the_plan(tmp_path):
    motion = tmp_path / "walk.trc"
    motion.write_bytes(b"")
    (job,) = resolve("plan", [str(MODEL)], noise_mm=1, motion=str(motion))
    assert job.input_files == (str(MODEL), str(motion)) and job.name == "diagnose_leg--noise1mm--walk.trc.plan"


def test_names_that_coincide_get_a_short_hash(tmp_path):
    for sub in ("day1", "day2"):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "walk.trc").write_bytes(b"")
    jobs = resolve("fit", [str(MODEL), str(tmp_path)])
    assert len(jobs) == 2 and jobs[0].name != jobs[1].name
    assert all(j.name.startswith("walk.trc--diagnose_leg-") and j.name.endswith(".fit") for j in jobs)
    assert inputs._slug("a b/c:d") == "a_b_c_d"


@pytest.mark.parametrize("how", ["folder", "glob", "path"])
def test_a_link_to_a_missing_trial_is_named_not_skipped(tmp_path, how):
    """A trial that is a link to a missing file is an error naming the link and its target, given in a folder, a
    glob or by path (a folder's and a glob's had been skipped without a word)."""
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "a.trc").write_bytes(b"")
    os.symlink(tmp_path / "gone.trc", tmp_path / "t" / "b.trc")
    spec = {"folder": tmp_path / "t", "glob": tmp_path / "t" / "*.trc", "path": tmp_path / "t" / "b.trc"}[how]
    with pytest.raises(InputError, match=r"b\.trc: a link to .*gone\.trc, which does not exist"):
        resolve("fit", [str(MODEL), str(spec)])
