"""Arguments out of range and output paths that cannot be written, for every verb: exit 2 before any work,
naming the option and the value or path, nothing created; never a traceback or exit 3 (the ``run`` fixture).

Before: ``simulate --seed -1`` was an internal error (NumPy takes no negative seed), ``--rate inf`` and
``--noise-mm inf`` passed the range checks, and an output path that is a file, a directory or under a missing
directory failed after the work with the result lost."""
from __future__ import annotations

import pytest
from hypothesis import given, strategies as st

import identcheck.api as api_mod

from fuzz_support import FUZZ, KNEE, LEG


class WorkStarted(BaseException):
    """Raised by a verb's library call under ``no_work``: not an Exception, so the CLI's guard lets it through."""


@pytest.fixture
def no_work(monkeypatch):
    """Every verb's library call replaced by one raising :class:`WorkStarted`: a refusal must come first."""
    def work(*args, **kwargs):
        raise WorkStarted

    for verb in ("rank", "table", "simulate", "plan", "derive", "diagnose", "fit", "identify", "verify", "batch"):
        monkeypatch.setattr(api_mod, verb, work)


def _argv(verb: str, tmp_path):
    return {"rank": ["rank", "revolute", "2", "1"], "table": ["table"], "plan": ["plan", LEG, "--fast"],
            "simulate": ["simulate", LEG, "--out", tmp_path / "x.trc"]}[verb]


@FUZZ
@given(verb=st.sampled_from(["rank", "table", "plan", "simulate"]), seed=st.integers(-10 ** 30, -1))
def test_a_negative_seed_is_a_usage_error(run, no_work, tmp_path, verb, seed):
    """Any negative --seed, for every verb that takes one: exit 2 from the parser, naming --seed."""
    res = run(_argv(verb, tmp_path) + ["--seed", str(seed)])
    assert res.code == 2 and res.names("--seed", str(seed)), res.err


@pytest.mark.parametrize("verb", ["rank", "table", "plan", "simulate"])
@pytest.mark.parametrize("seed", ["1.5", "abc", "", "0x10"])
def test_a_seed_that_is_not_a_whole_number_is_a_usage_error(run, no_work, tmp_path, verb, seed):
    res = run(_argv(verb, tmp_path) + ["--seed", seed])
    assert res.code == 2 and res.names("--seed"), res.err


@FUZZ
@given(option=st.sampled_from(["--frames", "--rate", "--noise-mm", "--occlusion", "--rom-deg"]),
       value=st.sampled_from(["inf", "-inf", "nan", "-1", "0", "1e9", "2000000", "400", "1.5"]))
def test_simulate_ranges(run, no_work, tmp_path, option, value):
    """simulate's numbers: a value outside its range (not finite, negative, a frame count beyond a million,
    an occlusion fraction of 1 or more, more than 360 degrees) is exit 2 naming the option; one inside starts
    the work."""
    out = tmp_path / "x.trc"
    try:
        res = run(["simulate", LEG, "--out", out, option, value])
    except WorkStarted:                           # the value was in range
        return
    assert res.code == 2 and res.names(option), res.err
    assert not out.exists()


@FUZZ
@given(value=st.one_of(st.integers(-10 ** 6, 14), st.integers(1001, 10 ** 9)))
def test_identify_precision_out_of_range(run, no_work, corpus, value):
    res = run(["identify", KNEE, corpus / "knee.trc", "--precision", str(value)])
    assert res.code == 2 and res.names("--precision", str(value)), res.err


@FUZZ
@given(frames=st.sampled_from(["a,b", "-1", "1,-2", "1.5", "1;2", ",", "1,,2"]))
def test_identify_frames_that_are_not_indices(run, no_work, corpus, frames):
    res = run(["identify", KNEE, corpus / "knee.trc", "--frames", frames])
    assert res.code == 2 and res.names("--frames"), res.err


@FUZZ
@given(frames=st.lists(st.integers(0, 40), min_size=2, max_size=8).filter(lambda f: len(set(f)) < len(f)))
def test_identify_frames_listed_twice_are_named(run, no_work, corpus, frames):
    """A frame listed twice (``5,5,5,5,5``) is no new sample: exit 2 naming --frames and the repeated frame, not
    exit 1 "degenerate data" after the work."""
    spec = ",".join(map(str, frames))
    res = run(["identify", KNEE, corpus / "knee.trc", "--frames", spec])
    again = next(f for f in frames if frames.count(f) > 1)
    assert res.code == 2 and res.names("--frames", "listed twice", str(again)), res.err


@FUZZ
@given(spec=st.sampled_from(["a:b", "1:2:3", "x", "500:900", "9:3", "1.5:8", ":-5"]))
def test_fit_frames_that_hold_no_frame_are_named(run, corpus, spec):
    """--frames START:END that is not a range or holds no frame of the trial: exit 2 naming --frames, the file
    and the file's own range."""
    res = run(["fit", LEG, corpus / "leg.trc", "--frames", spec])
    assert res.code == 2 and res.names("--frames", corpus / "leg.trc", "1"), res.err


@pytest.mark.parametrize("where", ["directory", "missing_parent", "file_as_parent"])
@pytest.mark.parametrize("argv, option", [
    (["simulate", LEG, "--out", "{}"], "--out"),
    (["simulate", LEG, "--out", "{tmp}/ok.trc", "--truth", "{}"], "--truth"),
    (["rank", "revolute", "2", "1", "--save", "{}"], "--save"),
    (["table", "--save", "{}"], "--save"),
    (["plan", LEG, "--figure", "{}"], "--figure"),
    (["fit", LEG, "{corpus}/leg.trc", "--export-markers", "{}"], "--export-markers"),
    (["fit", LEG, "{corpus}/leg.trc", "--report", "{}"], "--report"),
])
def test_an_output_file_that_cannot_be_written_is_refused_first(run, no_work, corpus, tmp_path, argv, option, where):
    """An output file that is a directory, under a missing directory, or under a file: exit 2 before any work,
    naming the option and the path; nothing created."""
    a_file = tmp_path / "a_file.txt"
    a_file.write_text("x")
    target = {"directory": tmp_path, "missing_parent": tmp_path / "missing" / "out.trc",
              "file_as_parent": a_file / "out.trc"}[where]
    args = [str(a).format(target, tmp=tmp_path, corpus=corpus) for a in argv]
    res = run(args)
    assert res.code == 2 and res.names(option, target), res.err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file.txt"]


@pytest.mark.parametrize("argv, option", [
    (["derive", "--out", "{}"], "--out"),
    (["diagnose", LEG, "{corpus}/leg.trc", "--plots", "{}"], "--plots"),
])
def test_an_output_folder_that_cannot_be_made_is_refused_first(run, no_work, corpus, tmp_path, argv, option):
    """An output folder that is a file, or under a file: exit 2 before any work, naming the option and path."""
    a_file = tmp_path / "a_file.txt"
    a_file.write_text("x")
    for target in (a_file, a_file / "sub"):
        res = run([str(a).format(target, corpus=corpus) for a in argv])
        assert res.code == 2 and res.names(option, target), res.err


@pytest.mark.parametrize("name", ["out.docx", "figure.toml", "plot"])
def test_a_figure_in_a_format_that_cannot_be_drawn_is_refused_first(run, no_work, tmp_path, name):
    """`plan --figure` with a suffix matplotlib cannot write used to end in a traceback (exit 3) after the
    work; now exit 2 before it, naming the option, the path and the formats."""
    res = run(["plan", LEG, "--fast", "--figure", str(tmp_path / name)])
    assert res.code == 2 and res.names("--figure", tmp_path / name, "PNG"), res.err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("argv, option", [
    (["plan", "{model}", "--figure", "{model}"], "--figure"),
    (["simulate", "{model}", "--out", "{model}"], "--out"),
])
def test_an_output_that_is_the_input_is_refused_first(run, no_work, tmp_path, argv, option):
    """Every output option, not only the trial exports, refuses to overwrite the verb's own input."""
    import hashlib
    import shutil

    model = tmp_path / "model.png" if option == "--figure" else tmp_path / "model.trc"
    shutil.copy(LEG, model)
    before = hashlib.sha256(model.read_bytes()).hexdigest()
    res = run([str(a).format(model=model) for a in argv])
    assert res.code == 2 and res.names(option, model), res.err
    assert hashlib.sha256(model.read_bytes()).hexdigest() == before


@pytest.mark.parametrize("argv, option", [
    (["simulate", "{model}", "--out", "{tmp}/t.trc", "--truth", "{model}"], "--truth"),
    (["simulate", LEG, "--out", "{tmp}/same.trc", "--truth", "{tmp}/same.trc"], "--truth"),
    (["rank", "revolute", "2", "1", "--save", "{tmp}/trial.trc"], "--save"),
    (["table", "--save", "{tmp}/out.csv"], "--save"),
])
def test_json_outputs_must_be_json_files_and_never_an_input_or_another_output(run, no_work, tmp_path, argv, option):
    """`simulate --truth` used to overwrite the model (or the trial it had just written) with JSON, and `--save`
    wrote JSON into a .trc: refused first, naming the option and the path."""
    import shutil

    model = tmp_path / "model.toml"
    shutil.copy(LEG, model)
    before = model.read_bytes()
    res = run([str(a).format(model=model, tmp=tmp_path) for a in argv])
    assert res.code == 2 and option in res.err and ".json" in res.err, res.err
    assert model.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["model.toml"]


def test_a_frame_range_starting_below_zero_reaches_the_option_s_own_check(run, corpus):
    """``--frames -5:10`` (a space, not '='), or abbreviated as argparse allows (``--fra -5:10``): argparse had taken
    -5:10 for an option and said only "expected one argument"; the value now reaches --frames' own check, which clamps
    the range to the file's frames with a warning, as ``--frames=-5:10`` did."""
    res = run(["fit", LEG, corpus / "leg.trc", "--frames", "-5:10", "--json"])
    assert res.code in (0, 1) and "--frames -5:10 reaches beyond the file's frames" in res.err, res.err
    res = run(["identify", KNEE, corpus / "knee.trc", "--frames", "-1,5"])
    assert res.code == 2 and "--frames -1,5" in res.err and "expected one argument" not in res.err, res.err
    res = run(["fit", LEG, corpus / "leg.trc", "--fra", "-5:10", "--json"])       # argparse's abbreviation
    assert res.code in (0, 1) and "--frames -5:10 reaches beyond the file's frames" in res.err, res.err


def test_only_frames_and_its_abbreviations_are_joined_to_a_negative_value():
    """What argparse would read as ``--frames`` (the option itself, or a prefix of it no other option shares) is
    joined to a following negative value; any other option, and a prefix other options share (``--f``), is left for
    argparse to judge."""
    from identcheck.cli import build_parser, joined_negative_values

    names = {opt for action in _all_actions(build_parser()) for opt in action.option_strings}
    for end in range(4, len("--frames") + 1):
        prefix = "--frames"[:end]
        assert [n for n in names if n.startswith(prefix)] == ["--frames"]     # (one name, in every verb)
        assert joined_negative_values([prefix, "-5:10"]) == [f"{prefix}=-5:10"]
    for word in ("--f", "--figure", "--fast", "--seed", "-5:10"):
        assert joined_negative_values([word, "-5"]) == [word, "-5"]


def _all_actions(parser):
    """Every action of `parser` and of its sub-commands' parsers."""
    import argparse

    for action in parser._actions:
        yield action
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from _all_actions(sub)


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "1e300", "1001"])
def test_a_plan_noise_no_capture_system_has_is_refused(run, value):
    """`plan --noise-mm` predicts a capture with that noise: zero, negative, not a number, or beyond a metre (at
    1e300 mm it had printed a 300-digit standard error) is refused, naming the option and the bound."""
    res = run(["plan", LEG, "--fast", "--noise-mm", value])
    assert res.code == 2 and f"--noise-mm {float(value)}" in res.err and "at most 1000" in res.err, res.err
