"""The public API (``import identcheck as ic``): the same numbers as the CLI's JSON, frozen results whose
``to_dict()`` is plain JSON, figures that leave matplotlib's backend alone, BLAS limited inside each call,
``--version``, and an import that stays light."""
from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

import identcheck as ic
from identcheck import cli
from real_data import real_file

ROOT = Path(__file__).resolve().parents[2]
EX = ROOT / "examples"
HIP = real_file("biobuddy_right_hip.c3d")


def cli_json(capsys, *argv) -> tuple[int, dict]:
    capsys.readouterr()
    rc = cli.main([*map(str, argv), "--json"])
    return rc, json.loads(capsys.readouterr().out)


def same_json(result) -> dict:
    """``result.to_dict()`` (or a dict) through the strict encoder and back: what the CLI prints, parsed."""
    return json.loads(json.dumps(result if isinstance(result, dict) else result.to_dict()))


@pytest.fixture(scope="module")
def trials(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("api")
    sparse = ic.simulate(EX / "sparse_leg.toml", tmp / "sparse_leg.trc", seed=3, noise_mm=0.3, n_frames=300)
    ic.simulate(EX / "diagnose_leg.toml", tmp / "dleg.trc", seed=7, noise_mm=0.5, n_frames=300,
                effect="marker_slip")
    return {"sparse_leg": tmp / "sparse_leg.trc", "dleg": tmp / "dleg.trc", "sim": sparse}


@pytest.mark.slow
def test_fit_is_the_cli_fit(trials, capsys):
    rc, doc = cli_json(capsys, "fit", EX / "sparse_leg.toml", trials["sparse_leg"])
    res = ic.fit(EX / "sparse_leg.toml", trials["sparse_leg"])
    assert isinstance(res, ic.FitResult)
    assert same_json(res) == doc
    assert rc == (0 if res.ok else 1)
    # objects in, the same answer out
    assert same_json(ic.fit(ic.load_model(EX / "sparse_leg.toml"), ic.read_trial(trials["sparse_leg"]))) == doc


@pytest.mark.skipif(not HIP.exists(), reason="real trials not available in examples/real or the shared folder")
def test_real_hip_fit_runs_the_label_screen_like_the_cli(capsys):
    """The library used to skip the label-swap screen the CLI ran (rms 8.98 mm against the CLI's 7.42 mm)."""
    rc, doc = cli_json(capsys, "fit", EX / "real_right_hip.toml", HIP)
    res = ic.fit(EX / "real_right_hip.toml", HIP)
    assert same_json(res) == doc
    assert res.joints["hip_r"]["rms_residual"] == doc["joints"]["hip_r"]["rms_residual"] < 8.5
    assert any("RLFE and RMFE" in w["message"] for w in res.warnings)


def test_diagnose_is_the_cli_diagnose(trials, capsys):
    rc, doc = cli_json(capsys, "diagnose", EX / "diagnose_leg.toml", trials["dleg"])
    res = ic.diagnose(EX / "diagnose_leg.toml", trials["dleg"])
    assert isinstance(res, ic.Diagnosis)
    assert same_json(res) == doc
    assert rc == (0 if res.consistent else 1)


def test_plan_is_the_cli_plan(capsys):
    rc, doc = cli_json(capsys, "plan", EX / "sparse_leg.toml", "--fast")
    res = ic.plan(EX / "sparse_leg.toml", motion=False, robust=False)
    assert isinstance(res, ic.PlanResult)
    assert same_json(res) == doc
    assert rc == (0 if res.all_identifiable else 1) == 1
    assert res.joints["knee_r"]["case"] == "revolute(2,1)"


@pytest.mark.slow
def test_identify_table_rank_verify_derive_are_the_cli_verbs(trials, capsys, tmp_path):
    from identcheck import api

    knee = tmp_path / "knee.c3d"
    ic.simulate(EX / "knee_21.toml", knee, seed=1)
    assert same_json(api.identify(EX / "knee_21.toml", knee)) == cli_json(capsys, "identify", EX / "knee_21.toml",
                                                                            knee)[1]
    assert same_json(ic.table(joints=("prismatic",))) == cli_json(capsys, "table", "--joint", "prismatic")[1]
    cert = ic.rank("revolute", 2, 1, seed=5)
    assert same_json(cert.sealed()) == cli_json(capsys, "rank", "revolute", 2, 1, "--seed", 5)[1]   # sealed: /2
    path = tmp_path / "cert.json"
    path.write_text(json.dumps(cert.sealed()))
    assert ic.verify(path).ok and same_json(ic.verify(path)) == cli_json(capsys, "verify", path)[1]
    out = tmp_path / "derivations"
    assert same_json(api.derive(out)) == cli_json(capsys, "derive", "--out", out)[1]


@pytest.mark.slow
def test_results_are_frozen_and_plain_json(trials, tmp_path):
    from identcheck import api

    sim = trials["sim"]
    results = [ic.fit(EX / "sparse_leg.toml", sim.trial), ic.plan(EX / "sparse_leg.toml", motion=False, robust=False),
               ic.diagnose(EX / "diagnose_leg.toml", trials["dleg"]), ic.table(joints=("prismatic",)),
               ic.rank("revolute", 2, 1), api.identify(EX / "hip_31.toml", ic.simulate(EX / "hip_31.toml", seed=5).trial)]
    path = tmp_path / "cert.json"
    path.write_text(json.dumps(results[4].to_dict()))
    results += [ic.verify(path), api.derive(tmp_path / "d")]
    types = (ic.FitResult, ic.PlanResult, ic.Diagnosis, ic.TableResult, ic.RankCertificate, ic.IdentifyResult,
             ic.VerifyResult, ic.DeriveResult)
    for res, kind in zip(results, types):
        assert isinstance(res, kind) and dataclasses.is_dataclass(res)
        name = dataclasses.fields(res)[0].name
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(res, name, None)
        json.dumps(res.to_dict())                     # no default=: anything not JSON raises here
    fit, plan = results[0], results[1]
    with pytest.raises(TypeError):                    # the documents inside are read-only too
        fit.joints["hip_r"]["marker_distances"]["RTHI"] = 0.0
    with pytest.raises(TypeError):
        plan.joints["knee_r"]["case"] = "x"
    with pytest.raises(TypeError):
        results[3].cases[0]["local"] = True          # the table's cached rows stay as computed


def test_figures_leave_the_backend_and_pyplot_alone(tmp_path):
    """A notebook's backend (here "pdf", set by the caller) is the same after drawing, and pyplot is never
    imported (no global figure state)."""
    script = f"""
import sys, matplotlib
matplotlib.use("pdf")
import identcheck as ic
from identcheck.report import diagnose_figures, plan_figure
before = matplotlib.get_backend()
plan = ic.plan({str(EX / 'sparse_leg.toml')!r}, motion=False, robust=False)
fig = plan_figure.figure(plan, title="sparse leg")
plan_figure.draw(plan, {str(tmp_path / 'plan.png')!r})
sim = ic.simulate({str(EX / 'diagnose_leg.toml')!r}, seed=7, noise_mm=0.5, n_frames=200, effect="marker_slip")
paths = diagnose_figures.write_all(ic.diagnose({str(EX / 'diagnose_leg.toml')!r}, sim.trial), {str(tmp_path / 'd')!r})
assert type(fig).__name__ == "Figure" and len(paths) >= 2
print(before, matplotlib.get_backend(), "matplotlib.pyplot" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.split() == ["pdf", "pdf", "False"]
    assert (tmp_path / "plan.png").stat().st_size > 10_000


def test_blas_is_limited_inside_a_call_and_restored_after():
    from threadpoolctl import threadpool_info

    seen = []
    before = {i["filepath"]: i["num_threads"] for i in threadpool_info()}
    ic.plan(EX / "sparse_leg.toml", motion=False, robust=False, witness=True,
            progress=lambda msg: seen.append({i["num_threads"] for i in threadpool_info()}))
    assert seen and all(s == {1} for s in seen)
    assert {i["filepath"]: i["num_threads"] for i in threadpool_info() if i["filepath"] in before} == before


def test_version(capsys):
    assert ic.__version__ and ic.__version__[0].isdigit()
    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"identcheck {ic.__version__}"


def test_the_parser_reads_the_version_only_when_asked():
    """Building the command line's parser (every verb does) does not import importlib.metadata: ``--version``
    reads the package metadata when it is given."""
    script = ("import sys, identcheck.cli as c; c.build_parser(); "
              "assert 'importlib.metadata' not in sys.modules, 'metadata read for every verb'")
    subprocess.run([sys.executable, "-c", script], check=True, cwd=ROOT)


def test_import_is_light_and_names_resolve():
    script = """
import sys
import identcheck as ic
assert not {"sympy", "scipy", "scipy.stats", "numpy"} & set(sys.modules), sorted(sys.modules)
names = ["__version__", "load_model", "read_trial", "simulate", "fit", "diagnose", "plan", "table", "rank", "verify",
         "FitResult", "Diagnosis", "PlanResult", "RankCertificate", "TableResult", "InputError", "DegenerateError",
         "IdentifiabilityWarning"]
for n in names[:10]:                                  # the verbs themselves import nothing heavy ...
    assert getattr(ic, n) is not None and (n.startswith("_") or getattr(ic, n).__doc__), n
assert "sympy" not in sys.modules
for n in names[10:]:                                  # ... the result types load their modules
    assert getattr(ic, n).__doc__, n
import identcheck.plan.analysis as analysis           # the subpackage under the verb's name still imports
from identcheck import derive                         # and derive is still the subpackage
assert callable(ic.plan) and analysis.__name__ == "identcheck.plan.analysis" and derive.__name__ == "identcheck.derive"
"""
    subprocess.run([sys.executable, "-c", script], check=True, cwd=ROOT)


def test_cli_and_fit_leave_heavy_modules_unloaded():
    """Importing the command line loads neither SymPy nor scipy.stats; a whole fit (closed-form starts, among
    them the revolute (2,1) and spherical solvers of the sparse leg, whole-tree fit, intervals) and
    ``identify`` (float64 and mpmath) load no SymPy, no scipy.stats and no matplotlib: the solvers' functions
    are committed generated code (identcheck.solve.generated)."""
    script = """
import sys, warnings
import identcheck.cli
assert not {"sympy", "scipy.stats", "matplotlib"} & set(sys.modules)
import identcheck as ic
from identcheck import api
warnings.simplefilter("ignore")
for model in ("examples/leg.toml", "examples/sparse_leg.toml"):
    sim = ic.simulate(model, n_frames=200, noise_mm=0.5, seed=1)
    ic.fit(model, sim.trial)
for model in ("examples/knee_21.toml", "examples/hip_22.toml", "examples/hip_31.toml"):
    sim = ic.simulate(model, n_frames=40, seed=1)
    assert api.identify(model, sim.trial).joints
api.identify("examples/knee_21.toml", ic.simulate("examples/knee_21.toml", n_frames=12, seed=1).trial, precision=30)
heavy = {"sympy", "scipy.stats", "matplotlib"} & set(sys.modules)
assert not heavy, heavy
"""
    subprocess.run([sys.executable, "-c", script], check=True, cwd=ROOT)


def test_a_plan_without_noise_loads_no_scipy():
    """``plan``'s verdicts, motion and robustness analyses are exact arithmetic: SciPy stays unloaded (its import
    was a third of the call), and so does NumPy (a sixth: the trial readers are loaded when a trial is read); with
    ``noise_mm`` the practical verdicts fit, and SciPy is loaded under the BLAS limit."""
    script = """
import sys
import identcheck as ic
res = ic.plan("examples/body16.toml").to_dict()
assert res["robustness"] and "scipy" not in sys.modules, sorted(m for m in sys.modules if m.startswith("scipy"))
assert "numpy" not in sys.modules
from identcheck import cli
assert cli.main(["plan", "examples/knee_21.toml", "--json"]) in (0, 1) and "numpy" not in sys.modules  # 1: an answer
from identcheck.io import Model, read_trc                         # the package's names still resolve, on use
assert Model.__module__ == "identcheck.io.model" and read_trc.__module__ == "identcheck.io.trc"
from identcheck import api
assert api._plan_is_numerical(noise_mm=1.0) and api._plan_is_numerical(witness=True)
assert not api._plan_is_numerical("m.toml", motion=False)
"""
    subprocess.run([sys.executable, "-c", script], check=True, cwd=ROOT)


def test_errors_are_the_public_ones(tmp_path):
    with pytest.raises(ic.InputError, match="missing.toml"):
        ic.load_model(tmp_path / "missing.toml")
    with pytest.raises(ic.InputError, match="file not found"):
        ic.verify(tmp_path / "none.json")
