"""``identcheck batch`` on a real Dask LocalCluster (2 worker processes) over a folder of simulated TRC and C3D
trials with one corrupt file and one static trial: the JSONs are the verbs' own, the summary has a row per
trial x joint and an error row, a second run resumes (skipping what is done), the inputs are never touched and
nothing is written outside --out. Also ``--scheduler``: diagnose and a plan sweep on a cluster started here.

In the normal lane (marked ``cluster``, not ``slow``): small trials (300 frames, a 2-joint model), about half a
minute on 2 cores."""
import json
import os
from pathlib import Path

import pytest

import identcheck
from identcheck import api, cli

pytest.importorskip("distributed")
pd = pytest.importorskip("pandas")
pytestmark = pytest.mark.cluster

ROOT = Path(__file__).resolve().parents[2]
MODEL = str(ROOT / "examples" / "diagnose_leg.toml")
GOOD = ("walk1.trc", "walk2.c3d", "deep/walk3.trc")


def _snapshot(folder: Path) -> dict:
    """Every file below `folder`: its bytes and modification time."""
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A folder of trials (mixed TRC / C3D, one static, one corrupt), its snapshot, and the first batch's run."""
    root = tmp_path_factory.mktemp("batch")
    trials = root / "trials"
    (trials / "deep").mkdir(parents=True)
    for seed, name in enumerate(GOOD, 1):
        api.simulate(MODEL, trials / name, seed=seed, n_frames=300, noise_mm=0.5)
    api.simulate(MODEL, trials / "static.c3d", seed=9, n_frames=300, noise_mm=0.5, rom_deg=0.0)   # one pose
    (trials / "bad.trc").write_text("PathFileType\t4\t(X/Y/Z)\tbad.trc\nnot a TRC file\n")
    return {"root": root, "trials": trials, "before": _snapshot(trials), "out": root / "out"}


@pytest.fixture(scope="module")
def first(work):
    """``identcheck batch fit MODEL trials/ --out out --workers 2`` (its exit code and stderr)."""
    import subprocess
    import sys

    listing = sorted(os.listdir(work["root"]))
    res = subprocess.run([sys.executable, "-m", "identcheck", "batch", "fit", MODEL, str(work["trials"]),
                          "--out", str(work["out"]), "--workers", "2", "--dashboard", ":0", "--json"],
                         capture_output=True, text=True, timeout=300)
    work["listing"] = listing
    return res


def test_fit_batch_writes_one_json_per_trial_and_the_summary(work, first):
    assert first.returncode == 1, first.stderr                      # some (not all) jobs failed: exit 1
    err = first.stderr
    assert "dashboard: http://" in err and "Traceback" not in err
    assert "5/5 [" in err and ("job/s" in err or "s/job" in err)     # progress: counts, rate (and ETA) on stderr
    doc = json.loads(first.stdout)
    assert (doc["jobs"], doc["done"], doc["skipped"], doc["failed"]) == (5, 4, 0, 1)
    out = work["out"]
    names = sorted(p.name for p in out.glob("*.json"))
    assert names == sorted(f"{Path(t).name}--diagnose_leg.fit.json" for t in GOOD + ("static.c3d",))
    df = pd.read_parquet(out / "summary.parquet")
    assert len(df) == 4 * 2 + 1 and set(df["joint"].dropna()) == {"hip", "knee"}
    csv = pd.read_csv(out / "summary.csv", keep_default_na=False)
    assert list(csv["job"]) == list(df["job"]) and list(csv.columns) == list(df.columns)
    assert set(df["identcheck_version"]) == {identcheck.__version__} and df["settings_hash"].nunique() == 1
    good = df[df["trial"].str.contains("walk")]
    assert (good["status"] == "done").all() and good["unique"].all() and (good["practical"] == "determined").all()
    assert (good["estimator"] == "whole-tree maximum likelihood").all() and (good["noise_mm"] > 0.3).all()
    assert all(json.loads(m)["RGT"] > 0 for m in good["marker_distances"])
    static = df[df["trial"].str.endswith("static.c3d")]                 # done, but the trial decides nothing
    assert (static["status"] == "done").all() and not static["unique"].any() and not static["ok"].any()


def test_a_bad_file_is_an_error_row_with_the_readers_message(work, first):
    df = pd.read_parquet(work["out"] / "summary.parquet")
    (err,) = df[df["status"] == "error"].itertuples()
    assert err.trial.endswith("bad.trc") and pd.isna(err.joint) and pd.isna(err.json)
    with pytest.raises(identcheck.InputError) as exc:
        api.read_trial(work["trials"] / "bad.trc")
    assert err.error == str(exc.value) and "Traceback" not in err.error
    assert not (work["out"] / "bad.trc--diagnose_leg.fit.json").exists()


def test_each_json_is_what_the_verb_prints(work, first, capsys):
    trial = work["trials"] / "walk2.c3d"
    assert cli.main(["fit", MODEL, str(trial), "--json"]) == 0
    assert (work["out"] / "walk2.c3d--diagnose_leg.fit.json").read_text() == capsys.readouterr().out


def test_a_rerun_completes_only_what_is_missing(work, first, monkeypatch):
    out = work["out"]
    lost = out / "walk1.trc--diagnose_leg.fit.json"               # as if killed before this job was written ...
    lost.unlink()
    (out / ".tmp-walk1.trc--diagnose_leg.fit.json.1.dead").write_text('{"partial')   # ... while writing it
    kept = {p.name: p.stat().st_mtime_ns for p in out.glob("*.json")}
    df = identcheck.batch("fit", [MODEL, str(work["trials"])], out, workers=2, dashboard=":0")
    status = df.drop_duplicates("job").set_index("job")["status"].to_dict()
    assert status.pop("walk1.trc--diagnose_leg.fit") == "done" and status.pop("bad.trc--diagnose_leg.fit") == "error"
    assert set(status.values()) == {"skipped"} and len(status) == 3
    assert {p.name: p.stat().st_mtime_ns for p in out.glob("*.json") if p.name in kept} == kept
    assert lost.exists() and not list(out.glob(".tmp-*"))
    first_df = pd.read_parquet(out / "summary.parquet")
    assert list(first_df["job"]) == list(df["job"])

    from identcheck.batch import runner

    def no_cluster(*a, **k):
        raise AssertionError("a cluster was started although every job was done")

    monkeypatch.setattr(runner, "_client", no_cluster)                # every job done: no cluster at all
    again = identcheck.batch("fit", [str(work["trials"] / "walk*.*"), str(work["trials"] / "deep")], out,
                             model=MODEL)
    assert set(again["status"]) == {"skipped"} and len(again.drop_duplicates("job")) == 3


def test_inputs_are_never_modified_and_nothing_is_written_outside_out(work, first):
    assert _snapshot(work["trials"]) == work["before"]
    assert sorted(os.listdir(work["root"])) == sorted(set(work["listing"]) | {"out"})
    assert not (work["out"] / ".identcheck-batch" / "dask").exists()    # the cluster's scratch space is gone


def test_diagnose_and_a_plan_sweep_on_an_existing_cluster(work, first, capsys):
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        address = cluster.scheduler_address
        out = work["root"] / "diag"
        code = cli.main(["batch", "diagnose", MODEL, str(work["trials"] / "walk1.trc"),
                         str(work["trials"] / "static.c3d"), "--out", str(out), "--scheduler", address])
        assert code == 1
        df = pd.read_csv(out / "summary.csv", keep_default_na=False)
        (err,) = df[df["status"] == "error"].itertuples()
        assert "static.c3d" in err.trial and "does not move relative to" in err.error
        good = df[df["status"] == "done"]
        assert list(good["joint"]) == ["hip", "knee"] and (good["effects"] == "[]").all()
        capsys.readouterr()

        out = work["root"] / "plan"
        df = identcheck.batch("plan", MODEL, out, noise_mm="0.5,2", motion="functional,flexion", fast=True,
                              frames=200, scheduler=address)
    assert len(df) == 2 * 2 * 2 and set(df["status"]) == {"done"}
    assert set(zip(df["noise_mm"], df["motion"])) == {(0.5, "functional"), (0.5, "flexion"), (2.0, "functional"),
                                                       (2.0, "flexion")}
    assert set(df[df["motion"] == "flexion"]["practical"]) == {"undetermined"}    # one axis leaves the hip free
    assert cli.main(["plan", MODEL, "--json", "--fast", "--noise-mm", "2", "--frames", "200"]) == 0
    assert (out / "diagnose_leg--noise2mm--functional.plan.json").read_text() == capsys.readouterr().out
