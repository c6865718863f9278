"""Inputs that would exhaust the machine or read without end, numbers Python reads but no capture writes,
outputs a full disk cuts short, arguments out of range and a model with nothing to fit: each an exit-2 (or
exit-1, for data that cannot decide) message naming the file, field or option, never a traceback, an exit 3, a
hang or a changed input (the ``run`` fixture).

Before: a FIFO or /dev/zero given as a trial or model was read without end (a hang, or memory until the machine
killed the run); a 1 MB cell in a TRC file took gigabytes (every cell of the table sized like it) and the error
quoted it whole; ``1_000`` and full-width digits were read as numbers; a C3D file written to a full disk was cut
short and reported written; a model without joints stopped ``diagnose`` and ``fit --report`` with a traceback;
``--dashboard xx:yy`` and ``batch plan --frames 5`` ran; a static trial was exit 2 for ``diagnose`` but exit 1
for ``fit``."""
from __future__ import annotations

import os
import threading

import numpy as np
import pytest
from hypothesis import given, strategies as st

from fuzz_support import DIAGNOSE_LEG, FUZZ, LEG


def _trc_lines(corpus) -> list[str]:
    return (corpus / "leg.trc").read_text().split("\n")


@pytest.mark.parametrize("role", ["trial", "model", "certificate"])
def test_a_fifo_is_refused_without_being_opened(run, corpus, tmp_path, role):
    """A FIFO no one writes to would block the first read for ever: it is refused by what it is, and a
    watchdog fails the test instead of hanging the suite if it is opened."""
    fifo = tmp_path / {"trial": "t.trc", "model": "m.toml", "certificate": "c.json"}[role]
    os.mkfifo(fifo)
    opened = threading.Timer(20.0, lambda: open(fifo, "wb").close())    # unblocks a reader, after the fact
    opened.start()
    try:
        argv = {"trial": ["fit", LEG, fifo], "model": ["fit", fifo, corpus / "leg.trc"],
                "certificate": ["verify", fifo]}[role]
        res = run(argv, inputs=())
    finally:
        opened.cancel()
    assert res.code == 2 and res.names(fifo, "not a regular file"), res.err


def test_a_device_is_refused_as_a_model(run, corpus):
    res = run(["fit", "/dev/zero", corpus / "leg.trc"], inputs=())
    assert res.code == 2 and res.names("/dev/zero", "not a regular file"), res.err


@FUZZ
@given(size=st.integers(65, 2_000_000), column=st.integers(0, 29), row=st.integers(0, 199))
def test_a_cell_too_long_for_a_number_is_named_and_quoted_short(run, corpus, tmp_path, size, column, row):
    lines = _trc_lines(corpus)
    cells = lines[6 + row].split("\t")
    cells[column % len(cells)] = "7" * size
    lines[6 + row] = "\t".join(cells)
    path = tmp_path / "long.trc"
    path.write_text("\n".join(lines))
    res = run(["fit", LEG, path])
    assert res.code == 2 and res.names(path, f"line {7 + row}, column {column % len(cells) + 1}",
                                       f"{size:,} characters"), res.err[:500]
    assert len(res.err) < 5000


@FUZZ
@given(kind=st.sampled_from(["1_000.5", "\uff11\uff12\uff13.4", "1\u0663.0", "12_3"]), row=st.integers(0, 199),
       marker=st.integers(0, 9), axis=st.integers(0, 2))
def test_numbers_no_capture_software_writes_are_named(run, corpus, tmp_path, kind, row, marker, axis):
    """Digit groups and digits of other scripts, which Python's float() reads: named by line and column."""
    lines = _trc_lines(corpus)
    cells = lines[6 + row].split("\t")
    cells[2 + 3 * marker + axis] = kind
    lines[6 + row] = "\t".join(cells)
    path = tmp_path / "digits.trc"
    path.write_text("\n".join(lines), encoding="utf-8")
    res = run(["fit", LEG, path])
    assert res.code == 2 and res.names(path, f"line {7 + row}, column {3 + 3 * marker + axis}",
                                       "not written in plain digits"), res.err


def test_a_fractional_frame_number_is_not_truncated(run, corpus, tmp_path):
    """Frame# 1.5, 2.5, ... would have been cast to 1, 2, ...: a warning says the rows are numbered instead."""
    lines = _trc_lines(corpus)
    for i in range(6, 206):
        cells = lines[i].split("\t")
        cells[0] = f"{int(cells[0])}.5"
        lines[i] = "\t".join(cells)
    path = tmp_path / "half.trc"
    path.write_text("\n".join(lines))
    res = run(["fit", LEG, path, "--json"])
    assert res.code in (0, 1) and "not a whole number at line 7" in res.out


@pytest.mark.parametrize("suffix", [".c3d", ".C3D"])
def test_a_c3d_file_cut_short_by_the_disk_is_no_success(run, corpus, tmp_path, monkeypatch, suffix):
    """ezc3d reports no failed write; a file the disk cut short is read back, refused, and neither it nor a
    temporary file is left."""
    import ezc3d

    write = ezc3d.c3d.write

    def cut(self, path, *args, **kwargs):
        write(self, path, *args, **kwargs)
        with open(path, "r+b") as fh:
            fh.truncate(4096)

    monkeypatch.setattr(ezc3d.c3d, "write", cut)
    out = tmp_path / f"sim{suffix}"
    res = run(["simulate", LEG, "--out", out, "--frames", "300"])
    assert res.code == 2 and res.names(out, "cannot write C3D file", "does not read back"), res.err
    assert os.listdir(tmp_path) == []


def test_a_model_without_joints_has_nothing_to_fit(run, corpus, tmp_path):
    model = tmp_path / "one.toml"
    model.write_text('units = "mm"\n\n[segments.pelvis]\nmarkers = ["LASI", "RASI", "SACR"]\n')
    report = tmp_path / "r.html"
    for argv in (["fit", model, corpus / "leg.trc", "--report", report], ["diagnose", model, corpus / "leg.trc"]):
        res = run(argv)
        assert res.code == 2 and res.names(model, "no joint", "skeleton"), res.err
    assert not report.exists()


@pytest.mark.parametrize("address", ["xx:yy", ":99999", "8787", ":-1", "host name:80"])
def test_a_dashboard_address_that_cannot_be_is_refused_before_any_work(run, corpus, tmp_path, address):
    res = run(["batch", "fit", LEG, corpus / "leg.trc", "--out", tmp_path / "o", "--dashboard", address])
    assert res.code == 2 and res.names("--dashboard", address), res.err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("frames", ["5", "0", "-3", "20001", "ten"])
def test_a_batch_plan_capture_length_out_of_range_is_refused(run, tmp_path, frames):
    res = run(["batch", "plan", LEG, "--out", tmp_path / "o", "--noise-mm", "1", "--frames", frames])
    assert res.code == 2 and res.names("--frames", frames, "10 to 20000"), res.err


@pytest.mark.parametrize("rate", ["1e300", "1e-300", "0.001", "2e6"])
def test_a_simulated_rate_whose_times_cannot_print_is_refused(run, tmp_path, rate):
    res = run(["simulate", LEG, "--out", tmp_path / "s.trc", "--rate", rate])
    assert res.code == 2 and res.names("--rate", "Hz") and not (tmp_path / "s.trc").exists(), res.err


def test_millimetres_labelled_centimetres_are_warned_about(corpus, tmp_path):
    """The reader warns of a frame spanning more than a capture volume in the file's units (the verbs then refuse
    the segments it makes too long: the test below)."""
    from identcheck.trial import Trial

    lines = _trc_lines(corpus)
    lines[2] = lines[2].replace("\tmm\t", "\tcm\t")
    path = tmp_path / "cm.trc"
    path.write_text("\n".join(lines))
    with pytest.warns(UserWarning, match="Units says cm.*in mm"):
        Trial.from_file(path)


@pytest.mark.parametrize("verb", ["fit", "diagnose"])
@pytest.mark.parametrize("spec", ["", " ", "1_0:50", "\uff11:50", "10:5_0"])
def test_a_frame_range_that_is_empty_or_not_plain_digits_is_refused(run, corpus, verb, spec):
    """``--frames=`` had meant every frame and ``1_0:50`` frames 10 to 50: both are refused, naming the option."""
    model = LEG if verb == "fit" else DIAGNOSE_LEG
    trial = corpus / ("leg.trc" if verb == "fit" else "dleg.trc")
    res = run([verb, model, trial, f"--frames={spec}"])
    assert res.code == 2 and res.names("--frames"), res.err


def test_a_batch_writing_into_its_input_folder_is_refused(run, corpus, tmp_path):
    import shutil

    folder = tmp_path / "trials"
    folder.mkdir()
    shutil.copy(corpus / "leg.trc", folder / "leg.trc")
    res = run(["batch", "fit", LEG, folder, "--out", folder])
    assert res.code == 2 and res.names("--out", "input folder"), res.err
    assert sorted(os.listdir(folder)) == ["leg.trc"]


def test_an_opensim_model_the_disk_refuses_is_exit_2_and_leaves_nothing(run, corpus, tmp_path, monkeypatch):
    """OpenSim reports a failed write with a RuntimeError of its own (seen on a full disk): exit 2 naming the
    option and the file, and no partial .osim (it had been a traceback)."""
    from identcheck.fit import osim

    if osim.opensim_missing():
        pytest.skip("OpenSim's Python package is not installed (identcheck[osim])")

    class Refusing:
        def printToXML(self, path):
            open(path, "w").write("<Op")                 # a start, then the disk is full
            raise RuntimeError("std::exception in 'bool OpenSim::Object::print': SimTK Exception thrown at Xml.cpp")

    monkeypatch.setattr(osim, "build_model", lambda fit, name="identcheck": Refusing())
    out = tmp_path / "m.osim"
    res = run(["fit", LEG, corpus / "leg.trc", "--export-osim", out])
    assert res.code == 2 and res.names("--export-osim", out, "cannot write the model"), res.err
    assert os.listdir(tmp_path) == []


def test_a_cluster_that_cannot_listen_is_exit_2_naming_the_dashboard(run, corpus, tmp_path):
    """A well-formed address the machine cannot listen on (a host that does not resolve): the local cluster does
    not start, which is said with the option (it had been a traceback)."""
    pytest.importorskip("distributed")
    res = run(["batch", "fit", LEG, corpus / "leg.trc", "--out", tmp_path / "o", "--dashboard",
               "no-such-host.invalid:0", "--workers", "1"])
    assert res.code == 2 and res.names("the local cluster did not start", "--dashboard no-such-host.invalid:0"), \
        res.err


def test_an_exported_marker_file_given_back_to_fit_says_where_it_came_from(run, corpus, tmp_path):
    out = tmp_path / "with_joints.trc"
    assert run(["fit", LEG, corpus / "leg.trc", "--export-markers", out]).code in (0, 1)
    res = run(["fit", LEG, out])
    assert res.code == 2 and res.names("virtual marker", "--export-markers", "use the trial it was exported from"), \
        res.err


def test_plan_on_a_recorded_motion_says_the_noise_is_the_trials_own(run, corpus):
    """With --motion TRIAL the practical verdicts are the recorded trial's fit, at its own noise: the text said
    '? mm noise'."""
    res = run(["plan", LEG, "--fast", "--noise-mm", "1", "--motion", corpus / "leg.trc"])
    assert res.code in (0, 1) and "the trial's own noise, measured" in res.out and "? mm" not in res.out, res.out


@pytest.mark.parametrize("verb", ["fit", "diagnose"])
def test_millimetres_in_a_file_that_says_cm_are_refused_by_the_segments_they_make(run, corpus, tmp_path, verb):
    """A lower limb in mm under a units field that says cm reads 10 times too large: the frame's span alone was only
    warned about (a capture volume can be large), and every joint was reported 10 times too far with exit 0. A rigid
    segment 3.7 m long is no body part: exit 2, naming the file, the segment, two of its markers and the units; the
    same numbers labelled mm pass this check."""
    lines = _trc_lines(corpus)
    fields = lines[2].split("\t")
    assert fields[4] == "mm"
    fields[4] = "cm"
    path = tmp_path / "in_mm_said_cm.trc"
    path.write_text("\n".join(lines[:2] + ["\t".join(fields)] + lines[3:]))
    res = run([verb, LEG, path, "--json"])
    assert res.code == 2 and "Traceback" not in res.err, res.err
    assert str(path) in res.err and "segment 'thigh_r'" in res.err and "units field" in res.err, res.err
    assert run(["fit", LEG, corpus / "leg.trc", "--json"]).code in (0, 1)


def test_frames_the_screens_left_out_are_named_when_too_few_are_left(run, tmp_path):
    """Random numbers under six labels: every frame of the file shows every marker, but the spike screen leaves most
    samples out, and the fit's start then finds two frames with three markers a segment. The error says so (it had
    said only that two frames showed three markers, as if the file lacked them), from `fit` and from `diagnose`."""
    rng = np.random.default_rng(5)
    labels = [f"W{i}" for i in range(6)]
    from identcheck.trial import Trial

    trial = tmp_path / "random.trc"
    Trial(rng.uniform(-1000.0, 1000.0, (200, 6, 3)), labels, 100.0).to_file(trial)
    model = tmp_path / "two.toml"
    model.write_text('units = "mm"\n[segments.a]\nmarkers = ["W0", "W1", "W2"]\n[segments.b]\n'
                     'markers = ["W3", "W4", "W5"]\n[joints.j]\ntype = "spherical"\nparent = "a"\nchild = "b"\n')
    for verb in ("fit", "diagnose"):     # diagnose had said only that no two markers were seen together in 10 frames
        res = run([verb, model, trial, "--json"])
        assert res.code == 2 and str(trial) in res.err, (verb, res.err)
        assert "screens left out" in res.err and "spikes" in res.err and "rigid" in res.err, (verb, res.err)


def test_skeleton_refuses_more_markers_than_its_grouping_ends_with(run, tmp_path):
    """Grouping compares every pair of markers and merges one group at a time: 3000 markers had not ended after
    180 s, with no end in sight. More than the limit is refused at once, naming the count and --segments."""
    from identcheck.infer.grouping import MAX_GROUPING_MARKERS
    from identcheck.trial import Trial

    n = MAX_GROUPING_MARKERS + 1
    path = tmp_path / "many.trc"
    Trial(np.random.default_rng(2).uniform(-500.0, 500.0, (12, n, 3)), [f"M{i}" for i in range(n)], 100.0).to_file(path)
    res = run(["skeleton", path, "--out", tmp_path / "s.toml"])
    assert res.code == 2 and str(path) in res.err and f"{n} markers" in res.err and "--segments" in res.err, res.err
    assert not (tmp_path / "s.toml").exists()
