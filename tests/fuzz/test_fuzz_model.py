"""Malformed model files (TOML), made from the bundled examples: cut after any line, any value replaced by one
of another type, nesting 100 000 deep, binary content, markers named like virtual ones; and large valid trees
(a deep chain, a wide star), which must be planned without a traceback.

Each goes through ``identcheck plan --fast``: exit 2 naming the file (and the key or line where there is one),
or exit 0/1 for a model that is still valid; never a traceback or exit 3 (the ``run`` fixture)."""
from __future__ import annotations

import json
import math
import time
import tomllib

import pytest
from hypothesis import given, strategies as st

from fuzz_support import FUZZ, LEG, ROOT

EXAMPLES = sorted((ROOT / "examples").glob("*.toml"))


def _toml(value) -> str:
    """`value` as a TOML value (enough for the models: strings, numbers, booleans, arrays, inline tables)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, (int, str)):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml(v)}" for k, v in value.items()) + "}"


def _dump(doc: dict) -> str:
    """A model dictionary as a TOML file: top-level keys, then one table per segment and joint."""
    tables = {k: v for k, v in doc.items() if isinstance(v, dict) and all(isinstance(t, dict) for t in v.values())}
    out = [f"{k} = {_toml(v)}" for k, v in doc.items() if k not in tables]   # before the first [table]
    for top, entries in tables.items():
        for name, table in entries.items():
            out.append(f"[{top}.{json.dumps(name)}]")
            out += [f"{k} = {_toml(v)}" for k, v in table.items()]
    return "\n".join(out) + "\n"


def _paths(doc, prefix=()):
    """Every key path of a parsed TOML document."""
    for k, v in doc.items():
        yield prefix + (k,)
        if isinstance(v, dict):
            yield from _paths(v, prefix + (k,))


VALUES = st.one_of(st.integers(-10 ** 20, 10 ** 20), st.floats(allow_nan=True, allow_infinity=True),
                   st.booleans(), st.text(max_size=12), st.lists(st.integers(-3, 3), max_size=4),
                   st.just({}), st.just({"x": 1}), st.just(["LASI", "LASI"]), st.just([1.0, 2.0, math.nan]))


@FUZZ
@given(example=st.sampled_from(EXAMPLES), cut=st.floats(0, 1))
def test_a_model_cut_after_any_line_is_planned_or_named(run, tmp_path, example, cut):
    """The first lines of an example, up to any line: a valid smaller model (exit 0/1) or exit 2 naming the
    file."""
    lines = example.read_text().splitlines()
    path = tmp_path / "cut.toml"
    path.write_text("\n".join(lines[:int(len(lines) * cut)]) + "\n")
    res = run(["plan", path, "--fast", "--json"])
    assert res.code in (0, 1) or (res.code == 2 and res.names(path)), res.err


@FUZZ
@given(data=st.data())
def test_any_value_of_another_type_is_named_by_its_key(run, tmp_path, data):
    """One key of examples/leg.toml given a value of another type or range (a number for a name list, NaN for a
    position, a table for a string...): exit 0/1 when the model is still valid, else exit 2 naming the file
    and the key."""
    doc = tomllib.loads(LEG.read_text())
    path_ = data.draw(st.sampled_from(sorted(_paths(doc), key=str)))
    target = doc
    for k in path_[:-1]:
        target = target[k]
    target[path_[-1]] = data.draw(VALUES)
    path = tmp_path / "changed.toml"
    path.write_text(_dump(doc))
    res = run(["plan", path, "--fast", "--json"])
    assert res.code in (0, 1) or (res.code == 2 and res.names(path)), res.err
    if res.code == 2 and len(path_) > 1 and "TOML syntax" not in res.err:
        assert any(part in res.err for part in path_[1:]), (path_, res.err)


@pytest.mark.parametrize("text, words", [
    ("x = " + "[" * 100_000 + "]" * 100_000 + "\n", ["nested too deeply"]),
    ("x = " + "{a = " * 5_000 + "1" + "}" * 5_000 + "\n", ["nested too deeply"]),
    (bytes(range(256)) * 4, ["not UTF-8"]),
    ("[segments.pelvis\nmarkers = []\n", ["TOML syntax error", "line 1"]),
])
def test_unparseable_model_files_are_named(run, tmp_path, text, words):
    """Nesting 100 000 deep (a RecursionError in the TOML parser: exit 3 before), binary content, a syntax
    error: exit 2 naming the file and the reason."""
    path = tmp_path / "bad.toml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    res = run(["plan", path, "--fast"])
    assert res.code == 2 and res.names(path, *words), res.err


@pytest.mark.parametrize("encode", [
    lambda t: t.encode("utf-8-sig"),                       # a byte-order mark (Windows editors)
    lambda t: t.replace("\n", "\r\n").encode(),            # CRLF line ends
    lambda t: t.encode("utf-16"),                          # "Unicode text" (UTF-16 with its mark)
], ids=["bom", "crlf", "utf16"])
def test_a_model_saved_by_another_editor_plans_the_same(run, tmp_path, encode):
    """The same model with a UTF-8 byte-order mark, CRLF line ends or as UTF-16: the same plan (a mark used
    to be a TOML syntax error at line 1, column 1)."""
    reference = run(["plan", LEG, "--fast", "--json"])
    path = tmp_path / "saved.toml"
    path.write_bytes(encode(LEG.read_text()))
    res = run(["plan", path, "--fast", "--json"])
    assert res.code == reference.code and json.loads(res.out) == json.loads(reference.out), res.err


@pytest.mark.parametrize("name, kind", [("hip_r.centre", "spherical"), ("knee_r.axis1", "revolute")])
def test_a_model_marker_named_like_a_virtual_one_is_named(run, tmp_path, name, kind):
    """A model marker named like a joint's centre or hinge-axis point: exit 2 naming the key and the joint."""
    path = tmp_path / "virtual.toml"
    path.write_text(LEG.read_text().replace('"RKNE"', json.dumps(name)))
    res = run(["plan", path, "--fast"])
    assert res.code == 2 and res.names(path, "segments.thigh_r.markers", repr(name), repr(name.split(".")[0])), res.err


def _tree(n_joints: int, star: bool) -> str:
    """A model of `n_joints` ball joints, three markers a segment: a chain (each segment the next one's parent)
    or a star (every segment a child of the root)."""
    segs = [f"[segments.s{i}]\nmarkers = [\"M{i}a\", \"M{i}b\", \"M{i}c\"]\n" for i in range(n_joints + 1)]
    joints = [f"[joints.j{i}]\ntype = \"spherical\"\nparent = \"s{0 if star else i - 1}\"\nchild = \"s{i}\"\n"
              for i in range(1, n_joints + 1)]
    return "\n".join(segs + joints)


@pytest.mark.parametrize("star", [False, True], ids=["chain", "star"])
def test_deep_chains_and_wide_stars_are_planned(run, tmp_path, star):
    """A 40-joint chain and a 40-joint star: planned (exit 0) within a minute; a 3000-joint one loads (the tree
    is walked breadth first, never recursively)."""
    path = tmp_path / "tree.toml"
    path.write_text(_tree(40, star))
    t0 = time.perf_counter()
    res = run(["plan", path, "--fast", "--json"])
    assert res.code == 0 and json.loads(res.out)["all_identifiable"], res.err
    assert time.perf_counter() - t0 < 60
    from identcheck.io.model import Model

    path.write_text(_tree(3000, star))
    model = Model.from_toml(path)
    assert len(model.joint_order) == 3000
