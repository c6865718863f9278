"""The documentation in docs/ stays in step with the code.

- docs/json.md: the verbs are run on the bundled examples (simulated trials, small plans, one table); every key
  documented there must appear in some real output (a key marked *optional* must appear in one, or at least be a
  key the code writes), and every key of the real outputs must be documented wherever its siblings are (the
  top-level, per-joint, per-effect and per-case keys always are). Also the batch summary's columns.
- docs/cli.md: every verb of ``identcheck --help`` and every option of each verb's ``--help`` are documented, and
  every verb's ``--help`` ends with an example and the exit codes.
- docs/model.md: every key and value the model reader accepts is documented, and every example model uses only
  documented keys.
- docs/api.md: what ``docs/build_api.py`` writes now.
- docs/contract.md: a verbatim copy of the shared CONTRACT.md (when that is present), with its one added line.

One run takes about a minute on one core (the table and the derivations are most of it).
"""
from __future__ import annotations

import importlib.util
import json
import re
import warnings
from pathlib import Path

import pytest

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

import identcheck.api as api
from identcheck.cli import build_parser
from identcheck.report import json_out

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
EX = ROOT / "examples"
SOURCE = ROOT / "identcheck"

ROW = re.compile(r"^\|\s*`([^`]+)`\s*\|([^|]*)\|")
SECTION = re.compile(r"^##\s+`?([\w -]+?)`?\s*$")


# ---------------------------------------------------------------------- docs/json.md as key patterns
def _parts(path: str) -> tuple:
    """``joints.JOINT.alternatives[].delta_chi2`` -> ('joints', 'JOINT', 'alternatives', 'delta_chi2'): list
    items are looked through."""
    return tuple(p.replace("[]", "") for p in path.split(".") if p.replace("[]", ""))


def documented(section: str) -> dict:
    """{pattern: optional} of the key table(s) under ``## section`` of docs/json.md. An all-capitals part
    (``JOINT``, ``MARKER``) stands for any key."""
    out, current = {}, None
    for line in (DOCS / "json.md").read_text(encoding="utf-8").splitlines():
        m = SECTION.match(line)
        if m:
            current = m.group(1).strip()
            continue
        m = ROW.match(line)
        if m and current == section:
            out[_parts(m.group(1))] = "optional" in m.group(2)
    assert out, f"docs/json.md has no key table under '## {section}'"
    return out


def _wild(part: str) -> bool:
    return part.isupper() and part.replace("_", "").isalpha()


def matches(pattern: tuple, path: tuple) -> bool:
    return len(pattern) == len(path) and all(p == k or _wild(p) for p, k in zip(pattern, path))


def paths(doc, prefix=()) -> set:
    """Every key path of a JSON document (list items looked through)."""
    out = set()
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.add(prefix + (k,))
            out |= paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for v in doc:
            out |= paths(v, prefix)
    return out


def in_source(key: str) -> bool:
    """The key is written by the code: a string literal ``"key"`` somewhere in identcheck/."""
    pattern = re.compile(r"[\"']" + re.escape(key) + r"[\"']")
    return any(pattern.search(p.read_text(encoding="utf-8")) for p in SOURCE.rglob("*.py"))


def check_section(section: str, docs: list) -> None:
    """Every documented key is in some output (optional: or written by the code); every output key whose
    siblings are documented is documented."""
    spec = documented(section)
    seen = set().union(*(paths(d) for d in docs))
    missing = [".".join(p) for p, optional in spec.items()
               if not any(matches(p, s) for s in seen) and not (optional and (_wild(p[-1]) or in_source(p[-1])))]
    assert not missing, f"docs/json.md ({section}) documents keys no output has: {missing}"
    undocumented = sorted(".".join(s) for s in seen
                          if not any(matches(p, s) for p in spec)
                          and (len(s) == 1 or any(len(p) == len(s) and matches(p[:-1], s[:-1]) for p in spec)))
    assert not undocumented, f"docs/json.md ({section}) does not document keys the output has: {undocumented}"


# ---------------------------------------------------------------------- the real outputs
def _json(result) -> dict:
    return json.loads(json_out.dumps(result))


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict:
    """verb -> the JSON documents of a few runs on the bundled examples, chosen to show most optional keys."""
    tmp = tmp_path_factory.mktemp("docs_sync")
    out: dict = {}
    add = lambda verb, result: out.setdefault(verb, []).append(_json(result))  # noqa: E731
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # simulate: the file, the truth, an injected effect
        from identcheck.report.text import simulate_summary
        sim = api.simulate(EX / "leg.toml", tmp / "leg.trc", seed=1, noise_mm=0.5, n_frames=300)
        add("simulate", simulate_summary(sim, tmp / "leg.trc"))
        slip = api.simulate(EX / "diagnose_leg.toml", tmp / "slip.trc", seed=3, noise_mm=0.5, n_frames=400,
                            effect="marker_slip")
        add("simulate", simulate_summary(slip, tmp / "slip.trc"))
        # fit: determined; revolute (2,1) alone; a label swap; skin motion; a joint without markers; Vicon prefixes
        add("fit", api.fit(EX / "leg.toml", tmp / "leg.trc"))
        for seed in (1, 6):         # which of the (2,1) knee's candidates the fit keeps as alternatives depends on
            #                         the last bits of the BLAS kernels (seed 1 keeps none on some CPUs): two trials
            api.simulate(EX / "knee_21.toml", tmp / "knee.trc", seed=seed, noise_mm=0.3, n_frames=300)
            add("fit", api.fit(EX / "knee_21.toml", tmp / "knee.trc"))
        api.simulate(EX / "diagnose_leg.toml", tmp / "swap.trc", seed=3, noise_mm=0.5, n_frames=400,
                     effect="marker_swap")
        add("fit", api.fit(EX / "diagnose_leg.toml", tmp / "swap.trc"))
        api.simulate(EX / "diagnose_leg.toml", tmp / "skin.trc", seed=3, noise_mm=0.5, n_frames=400,
                     effect="soft_tissue")
        add("fit", api.fit(EX / "diagnose_leg.toml", tmp / "skin.trc"))
        bare = tomllib.loads((EX / "leg.toml").read_text())
        bare["segments"]["foot_r"]["markers"] = []
        from identcheck.io.model import Model
        add("fit", api.fit(Model.from_dict(bare), sim.trial.replace(labels=["Sub:" + m for m in sim.trial.labels])))
        # diagnose: a marker slip
        add("diagnose", api.diagnose(EX / "diagnose_leg.toml", tmp / "slip.trc"))
        # plan: a full plan; the fewest markers; a witness; bare trunk and head; the propagation's rejection;
        # practical verdicts
        add("plan", api.plan(EX / "leg.toml", fewest=True))
        hip21 = {"segments": {"pelvis": {"markers": ["LASI", "RASI"]}, "thigh": {"markers": ["RTHI"]}},
                 "joints": {"hip": {"type": "spherical", "parent": "pelvis", "child": "thigh"}}}
        add("plan", api.plan(Model.from_dict(hip21), witness=True))
        body = tomllib.loads((EX / "body16.toml").read_text())
        add("plan", api.plan(Model.from_dict(body), robust=False))
        body["segments"]["trunk"]["markers"] = body["segments"]["head"]["markers"] = []
        add("plan", api.plan(Model.from_dict(body), robust=False, motion=False))
        add("plan", api.plan(EX / "sparse_leg.toml", robust=False, motion=False, noise_mm=1.0, frames=300))
        # identify: revolute (2,1) (four joints), spherical (3,1)
        api.simulate(EX / "knee_21.toml", tmp / "knee0.trc", seed=1, n_frames=60)
        add("identify", api.identify(EX / "knee_21.toml", tmp / "knee0.trc"))
        api.simulate(EX / "hip_31.toml", tmp / "hip31.trc", seed=1, n_frames=60)
        add("identify", api.identify(EX / "hip_31.toml", tmp / "hip31.trc"))
        # rank, verify (a good and a spoiled certificate), table, derive
        cert = api.rank("revolute", 2, 1)
        add("rank", cert.sealed())                       # what rank --json prints and --save writes
        add("rank", api.rank("spherical", 2, 2).sealed())
        json_out.write(tmp / "cert.json", cert.sealed())
        add("verify", api.verify(tmp / "cert.json"))
        spoiled = _json(cert)
        spoiled["rank"] += 1
        add("verify", api.verify(spoiled))
        add("table", api.table(joints=("revolute",)))
        add("derive", api.derive(tmp / "derive"))
    return out


VERBS = ("fit", "diagnose", "plan", "identify", "rank", "verify", "table", "simulate", "derive")


@pytest.mark.parametrize("verb", VERBS)
def test_json_keys_documented(runs, verb):
    check_section(verb, runs[verb])


def test_batch_json_and_summary_columns_documented(tmp_path):
    pd = pytest.importorskip("pandas")
    from identcheck.batch import summary

    row = {c: None for c in summary.COLUMNS}
    rows = [dict(row, job="a", status="done", ok=True), dict(row, job="b", status="error", error="bad file")]
    check_section("batch", [_json(summary.counts(pd.DataFrame(rows), tmp_path))])
    spec = [p[0] for p in documented("batch summary")]
    assert sorted(spec) == sorted(summary.COLUMNS), (
        f"docs/json.md (batch summary) and identcheck.batch.summary.COLUMNS differ: documented only "
        f"{sorted(set(spec) - set(summary.COLUMNS))}, in the code only {sorted(set(summary.COLUMNS) - set(spec))}")


def test_the_check_itself():
    """The matching rules the checks above rely on."""
    assert matches(("joints", "JOINT", "type"), ("joints", "hip_r", "type"))
    assert not matches(("joints", "JOINT", "type"), ("joints", "hip_r"))
    assert paths({"a": [{"b": 1}, {"c": {"D": 2}}]}) == {("a",), ("a", "b"), ("a", "c"), ("a", "c", "D")}
    assert _parts("joints.JOINT.alternatives[].delta_chi2") == ("joints", "JOINT", "alternatives", "delta_chi2")
    assert in_source("marker_distances") and not in_source("no_such_key_anywhere")


# ---------------------------------------------------------------------- docs/cli.md
def _subparsers(parser):
    import argparse

    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices


def test_cli_verbs_and_options_documented():
    text = (DOCS / "cli.md").read_text(encoding="utf-8")
    parser = build_parser()
    problems = []
    top = {o for a in parser._actions for o in a.option_strings}
    for opt in top:
        if opt not in text:
            problems.append(f"identcheck {opt}")
    sections = re.split(r"^## ", text, flags=re.M)
    for verb, sub in _subparsers(parser).items():
        body = next((s for s in sections if re.match(rf"`?identcheck {verb}\b", s)), None)
        if body is None:
            problems.append(f"verb {verb}: no '## identcheck {verb}' section")
            continue
        rows = {cell.split()[0] for cell in re.findall(r"^\|\s*`([^`]+)`", body, flags=re.M)}
        for action in sub._actions:
            for opt in action.option_strings:
                if opt not in ("-h", "--help") and opt not in top and opt not in rows:    # (top: documented once)
                    problems.append(f"identcheck {verb} {opt} (a row '| `{opt} ...` |' of its table)")
            if not action.option_strings and action.dest != "help":
                name = (action.metavar or action.dest).upper()
                if name not in rows and name + "..." not in rows:
                    problems.append(f"identcheck {verb}: argument {name} (a row '| `{name}` |' of its table)")
    assert not problems, f"docs/cli.md does not document: {problems}"


def test_every_verb_help_has_an_example_and_exit_codes():
    problems = []
    for verb, sub in _subparsers(build_parser()).items():
        helptext = sub.format_help()
        if not re.search(rf"^example:\n  identcheck {verb}\b", helptext, flags=re.M):
            problems.append(f"{verb}: no one-line example ('example:' then 'identcheck {verb} ...')")
        if not re.search(r"^exit codes:", helptext, flags=re.M) or not all(f"  {c} " in helptext for c in "023"):
            problems.append(f"{verb}: no exit codes (0, 2, 3 at least) in the epilog")
    assert not problems, problems


# ---------------------------------------------------------------------- docs/model.md
def test_model_reference_covers_the_reader_and_the_examples():
    from identcheck.io import model

    text = (DOCS / "model.md").read_text(encoding="utf-8")
    names = set(re.findall(r"`([A-Za-z_][\w.]*)`", text))
    need = set(model.TOP_KEYS) | set(model.SEGMENT_KEYS) | set(model.JOINT_KEYS) | set(model.JOINT_TYPES) \
        | set(model.MODEL_UNITS)
    assert not sorted(need - names), f"docs/model.md does not document {sorted(need - names)}"
    used = set()
    files = sorted(EX.rglob("*.toml"))
    for path in files:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
        model.Model.from_dict(doc, source=str(path))                      # every example is a valid model
        used |= set(doc)
        for seg in doc.get("segments", {}).values():
            used |= set(seg)
        for joint in doc.get("joints", {}).values():
            used |= set(joint)
    assert files and not sorted(used - names), f"examples use keys docs/model.md does not document: {used - names}"
    example = re.search(r"```toml\n(.*?)```", text, flags=re.S).group(1)          # the page's own full example
    assert len(model.Model.from_dict(tomllib.loads(example)).joints) == 3


# ---------------------------------------------------------------------- docs/api.md, docs/contract.md
def test_api_reference_is_up_to_date():
    spec = importlib.util.spec_from_file_location("build_api", DOCS / "build_api.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    assert (DOCS / "api.md").read_text(encoding="utf-8") == build.render(), \
        "docs/api.md is out of date: run python docs/build_api.py"


SHARED_CONTRACT = ROOT.parent / "shared" / "CONTRACT.md"


@pytest.mark.skipif(not SHARED_CONTRACT.exists(), reason="no shared CONTRACT.md beside the repository")
def test_contract_is_the_shared_one():
    ours = (DOCS / "contract.md").read_text(encoding="utf-8").splitlines(keepends=True)
    shared = SHARED_CONTRACT.read_text(encoding="utf-8").splitlines(keepends=True)
    added = [line for line in ours if line.startswith("> **This is identcheck's public interface**")]
    assert len(added) == 1
    i = ours.index(added[0])
    assert ours[:i - 1] + ours[i + 1:] == shared, "docs/contract.md differs from the shared CONTRACT.md: copy it again"
