"""identcheck.batch.store: whole files or none; a job counts as done only for the same inputs, settings, version
and intact JSON."""
import json
import os
from pathlib import Path

import pytest

from identcheck.batch import store as store_mod
from identcheck.batch.inputs import resolve
from identcheck.batch.store import Store, input_hash
from identcheck.errors import InputError

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "examples" / "diagnose_leg.toml"


def test_input_hash_is_of_the_bytes_in_order(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.write_bytes(b"ab")
    b.write_bytes(b"c")
    h = input_hash([a, b])
    assert h == input_hash([a, b]) and h != input_hash([b, a])
    b.write_bytes(b"")
    a.write_bytes(b"abc")                                   # same concatenation, other files: another hash
    assert input_hash([a, b]) != h


def test_done_needs_the_same_inputs_settings_version_and_an_intact_json(tmp_path):
    trial = tmp_path / "a.trc"
    trial.write_bytes(b"data")
    job = resolve("fit", [str(MODEL), str(trial)])[0]
    s = Store(tmp_path / "out")
    s.prepare()
    sha = input_hash(job.input_files)
    assert s.done(job, sha, "1.0") is None
    s.save(job, '{"joints": {}}\n', {"input_hash": sha, "settings_hash": job.settings_hash,
                                      "identcheck_version": "1.0", "ok": True})
    assert s.done(job, sha, "1.0")["ok"] is True and s.read(job) == {"joints": {}}
    assert s.done(job, sha, "1.1") is None                                    # another version
    assert s.done(job, "0" * 64, "1.0") is None                               # other input bytes
    other = resolve("fit", [str(MODEL), str(trial)], frames="1:5")[0]
    assert other.name != job.name
    assert s.done(type(job)(**{**job.__dict__, "settings": other.settings}), sha, "1.0") is None  # other settings
    s.json_path(job).write_text('{"joints": {"edited": 1}}\n')                 # the JSON edited since
    assert s.done(job, sha, "1.0") is None
    s.discard(job)
    assert not s.json_path(job).exists() and not s.record_path(job).exists()


def test_prepare_removes_what_a_killed_run_left(tmp_path):
    out = tmp_path / "out"
    (out / store_mod.STATE).mkdir(parents=True)
    (out / ".tmp-a.json.123.abcd").write_text("{partial")
    (out / store_mod.STATE / ".tmp-a.json.123.abcd").write_text("{partial")
    (out / store_mod.STATE / "dask" / "worker-1").mkdir(parents=True)
    (out / "keep.json").write_text("{}")
    Store(out).clean()
    assert sorted(p.name for p in out.iterdir()) == [store_mod.STATE, "keep.json"]
    assert list((out / store_mod.STATE).iterdir()) == []
    Store(tmp_path / "none").clean()                       # nothing there: nothing created
    assert not (tmp_path / "none").exists()
    json.loads((out / "keep.json").read_text())


def test_a_second_run_into_a_held_folder_is_refused_naming_the_holder(tmp_path):
    """Two runs into one output folder would clean each other's temporary files and each write a summary of its own
    jobs only: while one holds the folder, another is refused with the holder's process id; once it ends, the
    folder is free again."""
    out = tmp_path / "out"
    with Store(out).locked():
        with pytest.raises(InputError, match=rf"another identcheck batch \(process {os.getpid()}\) is writing"):
            with Store(out).locked():
                pass
    with Store(out).locked():
        pass
