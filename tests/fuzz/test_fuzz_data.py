"""Degenerate data in well-formed files: one or two frames, two markers on one trajectory, a marker never
visible, a 1e30 sample, a static trial. Before, these ended in "no frame has a valid pose" or "SVD did not
converge" naming neither the file nor the marker, or in a confident wrong answer.

Each goes through ``fit``, ``identify`` and ``diagnose``: exit 2 naming the file and the marker, joint or frame,
or exit 1 with the reason (a static trial is a negative answer, not bad input); never a traceback or exit 3,
the file unchanged (the ``run`` fixture)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, strategies as st

from identcheck.io.trc import read_trc, write_trc

from fuzz_support import DIAGNOSE_LEG, FUZZ, KNEE, LEG

VERBS = {"fit": (LEG, "leg.trc"), "identify": (KNEE, "knee.trc"), "diagnose": (DIAGNOSE_LEG, "dleg.trc")}


def _variant(corpus, tmp_path, verb: str, change, name: str):
    """The verb's model and a copy of its reference trial with `change(xyz, labels)` applied (in mm)."""
    model, trial = VERBS[verb]
    data = read_trc(corpus / trial)
    xyz = data.xyz.copy()
    xyz = change(xyz, data.labels)
    path = tmp_path / f"{verb}_{name}.trc"
    write_trc(path, xyz, data.labels, data.rate_hz)
    return model, path, data.labels


@pytest.mark.parametrize("verb", VERBS)
@pytest.mark.parametrize("n", [1, 2])
def test_a_trial_of_one_or_two_frames_is_named(run, corpus, tmp_path, verb, n):
    """One or two frames: exit 2 naming the file (and, for fit, the joint that needs more)."""
    model, path, _ = _variant(corpus, tmp_path, verb, lambda xyz, labels: xyz[:n], f"{n}frames")
    res = run([verb, model, path])
    assert res.code == 2 and res.names(path), res.err
    if verb == "fit":
        assert res.names("joint 'hip_r'", "frame"), res.err


@FUZZ
@given(verb=st.sampled_from(sorted(VERBS)), pair=st.tuples(st.integers(0, 8), st.integers(0, 8)),
       offset=st.sampled_from([0.0, 1e-9, 0.3]))
def test_two_markers_on_one_trajectory_are_named(run, corpus, tmp_path, verb, pair, offset):
    """One marker's trajectory copied onto another (exactly, or within 0.3 mm): exit 2 naming both markers and
    the file (before: 'no frame has a valid pose', or a fit that went on with a wrong segment)."""
    a, b = pair
    n_markers = {"fit": 10, "identify": 3, "diagnose": 9}[verb]
    a, b = a % n_markers, b % n_markers
    if a == b:
        return

    def copy(xyz, labels):
        xyz[:, b] = xyz[:, a] + offset
        return xyz

    model, path, labels = _variant(corpus, tmp_path, verb, copy, "twins")
    res = run([verb, model, path])
    assert res.code == 2 and res.names(path, repr(labels[a]), repr(labels[b]), "coincide"), res.err


@pytest.mark.parametrize("verb", VERBS)
def test_a_marker_never_visible_is_named(run, corpus, tmp_path, verb):
    """A model marker whose every sample is empty: exit 2 naming it (before, fit dropped it silently)."""
    def hide(xyz, labels):
        xyz[:, 1] = np.nan
        return xyz

    model, path, labels = _variant(corpus, tmp_path, verb, hide, "blind")
    res = run([verb, model, path])
    assert res.code == 2 and res.names(path, repr(labels[1]), "never visible"), res.err


@FUZZ
@given(verb=st.sampled_from(sorted(VERBS)), frame=st.integers(0, 99), marker=st.integers(0, 2),
       value=st.sampled_from([1e30, -1e30, 2e6]))
def test_a_sample_far_beyond_the_volume_is_named(run, corpus, tmp_path, verb, frame, marker, value):
    """One coordinate of one sample set to 1e30 (a sentinel some exporters write for 'missing') or 2 km: exit 2
    naming the TRC line and the marker (before: no valid pose in any frame, or 'coplanar' from identify)."""
    def spike(xyz, labels):
        xyz[frame, marker, 2] = value
        return xyz

    model, path, labels = _variant(corpus, tmp_path, verb, spike, "spike")
    res = run([verb, model, path])
    assert res.code == 2 and res.names(path, f"line {7 + frame}", repr(labels[marker])), res.err


def test_a_static_trial_is_a_negative_answer_or_named(run, corpus, tmp_path):
    """Every frame the same (no motion): fit answers that nothing is determined (exit 1, each joint with its
    reason); diagnose answers degenerate data, naming the file (exit 1; it had refused the trial as bad input,
    exit 2, for the noise it could not estimate)."""
    model, path, _ = _variant(corpus, tmp_path, "fit", lambda xyz, labels: np.repeat(xyz[:1], 200, axis=0), "static")
    res = run(["fit", model, path, "--json"])
    assert res.code == 1, res.err
    model, path, _ = _variant(corpus, tmp_path, "diagnose", lambda xyz, labels: np.repeat(xyz[:1], 200, axis=0),
                              "static")
    res = run(["diagnose", model, path])
    assert res.code == 1 and res.names(path) and "every frame is the same" in res.err, res.err
