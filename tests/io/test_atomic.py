"""identcheck.io.atomic: a file is written whole or not at all, whoever writes it, and a failed write leaves the
previous file and no temporary one."""
import os

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identcheck.io import atomic


def _umask() -> int:
    old = os.umask(0)
    os.umask(old)
    return old


@settings(max_examples=20, deadline=None)
@given(st.binary(max_size=5000) | st.text(max_size=2000))
def test_atomic_write_leaves_the_content_and_no_temporary_file(tmp_path_factory, data):
    folder = tmp_path_factory.mktemp("w")
    target = folder / "a.json"
    atomic.atomic_write(target, data)
    want = data.encode("utf-8") if isinstance(data, str) else data
    assert target.read_bytes() == want and os.listdir(folder) == ["a.json"]
    assert oct(target.stat().st_mode & 0o777) == oct(0o666 & ~_umask())


def test_a_write_killed_before_the_move_leaves_the_previous_file(tmp_path, monkeypatch):
    target = tmp_path / "a.json"
    atomic.atomic_write(target, b"{}\n")

    def killed(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic.os, "replace", killed)
    with pytest.raises(KeyboardInterrupt):
        atomic.atomic_write(target, b"new")
    assert target.read_bytes() == b"{}\n" and os.listdir(tmp_path) == ["a.json"]


def test_a_library_that_fails_midway_leaves_no_partial_file(tmp_path):
    target = tmp_path / "m.npy"
    with pytest.raises(RuntimeError):
        with atomic.replacing(target) as tmp:
            assert tmp.parent == tmp_path and tmp.name.endswith("m.npy")
            np.save(tmp, np.zeros(10))
            raise RuntimeError("the library gave up")
    assert os.listdir(tmp_path) == []
    with atomic.replacing(target) as tmp:
        np.save(tmp, np.arange(3))
    assert np.array_equal(np.load(target), np.arange(3)) and os.listdir(tmp_path) == ["m.npy"]
