"""``identcheck batch`` arguments, without a cluster: a missing extra or a bad argument is exit 2 with one clear
message and nothing written."""
import os
import sys
from pathlib import Path

import pytest

import identcheck
from identcheck import cli

ROOT = Path(__file__).resolve().parents[2]
MODEL = str(ROOT / "examples" / "diagnose_leg.toml")


def test_missing_extra_is_exit_2_naming_the_install(tmp_path, monkeypatch, capsys):
    (tmp_path / "a.trc").write_bytes(b"")
    monkeypatch.setitem(sys.modules, "distributed", None)            # as if not installed
    out = tmp_path / "out"
    assert cli.main(["batch", "fit", MODEL, str(tmp_path / "a.trc"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "pip install 'identcheck[batch]'" in err and "distributed" in err and "Traceback" not in err
    assert not out.exists()
    with pytest.raises(ImportError, match=r"pip install 'identcheck\[batch\]'"):
        identcheck.batch("fit", [str(tmp_path / "a.trc")], out, model=MODEL)


def test_bad_arguments_are_exit_2_before_any_work(tmp_path, capsys):
    out = tmp_path / "out"
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "a.trc").write_bytes(b"")
    for argv, msg in (([str(tmp_path / "t")], "trials without a model"),
                      ([MODEL, str(tmp_path / "nope")], "nope: no such file or folder"),
                      ([MODEL, str(tmp_path / "t"), "--workers", "0"], "--workers 0: 1 or more"),
                      ([MODEL, str(tmp_path / "t"), "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"],
                       "with --scheduler the cluster's own workers run the jobs"),
                      ([str(tmp_path / "t" / "a.trc"), "--model", str(tmp_path / "t" / "a.trc")],
                       "a.trc is a trial"),
                      ([MODEL, str(tmp_path / "t"), "--workers", str(cli.MAX_WORKERS_PER_CPU * ((os.cpu_count() or 1))
                                                                    + 1)], "per CPU"),
                      ([MODEL, str(tmp_path / "t"), "--noise-mm", "1"], "--noise-mm: an option of batch plan only"),
                      ([MODEL, str(tmp_path / "t"), "--seed", "0", "--fast"],
                       "--seed, --fast: options of batch plan only")):
        assert cli.main(["batch", "fit", *argv, "--out", str(out)]) == 2, argv
        err = capsys.readouterr().err
        assert msg in err and "Traceback" not in err, (argv, err)
    assert cli.main(["batch", "identify", MODEL, "--out", str(out)]) == 2
    assert "invalid choice: 'identify'" in capsys.readouterr().err
    assert cli.main(["batch", "plan", MODEL, "--noise-mm", "1,x", "--out", str(out)]) == 2
    assert "--noise-mm x: a positive noise level" in capsys.readouterr().err
    with pytest.raises(identcheck.InputError, match="with --scheduler the cluster's own workers"):
        identcheck.batch("fit", [str(tmp_path / "t")], out, model=MODEL, workers=2, scheduler="tcp://127.0.0.1:1")
    assert not out.exists()


def test_batch_is_a_verb_with_its_help(capsys):
    assert cli.main(["batch", "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: identcheck batch") and "--scheduler" in out and "--workers" in out
    assert identcheck.batch.__doc__ and "Dask" in identcheck.batch.__doc__
    import identcheck.batch.runner as runner                          # the subpackage still imports by its name
    assert runner.__name__ == "identcheck.batch.runner"
