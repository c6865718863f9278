"""Library calls with arguments of the wrong kind: an InputError naming the argument, what it expects and what it
got, never Python's own error from deep inside (an int had been read as an open file descriptor, "Bad file
descriptor"; a list or an array had failed in pathlib; a joint type the table does not know had given an empty
table; a certificate saved with a byte-order mark had been refused as not JSON)."""
from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import identcheck as ic

NOT_A_PATH = st.one_of(st.integers(), st.floats(allow_nan=False), st.none(), st.booleans(),
                       st.lists(st.integers(), max_size=3), st.builds(lambda n: np.zeros((n, 2, 3)), st.integers(1, 4)))


@settings(max_examples=25, deadline=None)
@given(value=NOT_A_PATH)
def test_a_model_or_trial_that_names_no_file_is_refused_by_its_argument(examples, value):
    model = examples / "knee_21.toml"
    for call, what in ((lambda: ic.load_model(value), "model"), (lambda: ic.plan(value), "model"),
                       (lambda: ic.read_trial(value), "trial"), (lambda: ic.fit(model, value), "trial"),
                       (lambda: ic.diagnose(model, value), "trial"), (lambda: ic.fit(value, "t.trc"), "model"),
                       (lambda: ic.simulate(model, value, n_frames=10), "out")):
        if what == "out" and value is None:
            continue                                        # (no output file: simulate only)
        with pytest.raises(ic.InputError) as info:
            call()
        msg = str(info.value)
        assert msg.startswith(f"{what}: expected") and f"got {type(value).__name__}" in msg and "\n" not in msg


@pytest.mark.parametrize("call, what", [
    (lambda: ic.plan("x.toml", noise_mm="a"), "noise_mm"),
    (lambda: ic.plan("x.toml", seed=1.5), "seed"),
    (lambda: ic.rank("revolute", "a", 1), "p"),
    (lambda: ic.rank("revolute", 2, None), "q"),
    (lambda: ic.table(seed="s"), "seed"),
    (lambda: ic.verify(5), "certificate"),
])
def test_numbers_and_names_of_the_wrong_kind_are_named(call, what):
    with pytest.raises(ic.InputError) as info:
        call()
    assert str(info.value).startswith(f"{what}: expected"), str(info.value)


def test_a_joint_type_the_table_does_not_know_is_refused():
    with pytest.raises(ic.InputError) as info:
        ic.table(joints=["revolute", "bogus"])
    assert "'bogus'" in str(info.value) and "revolute" in str(info.value)


def test_a_certificate_saved_with_a_byte_order_mark_verifies(tmp_path):
    cert = ic.rank("revolute", 2, 1, seed=3)
    path = tmp_path / "cert.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(cert.to_dict()).encode())
    assert ic.verify(path).ok
