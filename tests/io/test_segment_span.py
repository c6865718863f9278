"""A model segment whose markers lie farther apart than any body segment (a units field that scaled the numbers up)
is refused by :meth:`Trial.require_usable`, whatever part of the frames the two markers share; a declared
``length_mm`` lets a body truly that long through. A segment declared far longer than the markers reach (a units
field that scaled the numbers down: centimetres in a file that says mm) is refused too."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from identcheck.errors import InputError
from identcheck.trial import LONGEST_SEGMENT_MM, SMALLEST_REACH_SHARE, Trial


def _trial(apart_mm: float, together: float, seed: int, n_frames: int = 200) -> Trial:
    """Three markers on one segment: A and B `apart_mm` apart, C near A; B is hidden in all but a share `together`
    of the frames, and A in some of the others (so that frames with one marker of the pair seen are many)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(0.0, 50.0, (n_frames, 3))
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    xyz = np.stack([a, a + apart_mm * direction, a + 40.0 * np.roll(direction, 1)], axis=1)
    seen_b = rng.random(n_frames) < together
    seen_b[0] = True
    xyz[~seen_b, 1] = np.nan
    hide_a = ~seen_b & (rng.random(n_frames) < 0.5)
    xyz[hide_a, 0] = np.nan
    return Trial(xyz, ["A", "B", "C"], 100.0, source="span.trc")


@settings(max_examples=30, deadline=None)
@given(st.floats(1.05, 20.0), st.floats(0.05, 1.0), st.integers(0, 2**32 - 1))
def test_a_pair_farther_apart_than_a_segment_is_refused_however_little_it_is_seen_together(factor, together, seed):
    trial = _trial(factor * LONGEST_SEGMENT_MM, together, seed)
    where = {m: "thigh" for m in "ABC"}
    with pytest.raises(InputError) as info:
        trial.require_usable(["A", "B", "C"], where)
    msg = str(info.value)
    pair = msg.split("m (", 1)[1].split(", median", 1)[0]                     # B is far from both A and C
    assert "span.trc" in msg and "segment 'thigh'" in msg and "'B'" in pair and "units field" in msg, msg
    trial.require_usable(["A", "B", "C"], where, {"thigh": factor * LONGEST_SEGMENT_MM})      # declared: passes


@settings(max_examples=30, deadline=None)
@given(st.floats(10.0, 0.95 * LONGEST_SEGMENT_MM), st.floats(0.05, 1.0), st.integers(0, 2**32 - 1))
def test_segments_of_body_size_pass(apart_mm, together, seed):
    _trial(apart_mm, together, seed).require_usable(["A", "B", "C"], {m: "thigh" for m in "ABC"})


def test_markers_never_seen_together_say_nothing_of_the_span():
    xyz = np.full((10, 2, 3), np.nan)
    xyz[:5, 0] = 0.0
    xyz[5:, 1] = 10_000.0
    Trial(xyz, ["A", "B"], 100.0).require_usable(["A", "B"], {"A": "s", "B": "s"})


@settings(max_examples=30, deadline=None)
@given(st.floats(1000.0, 2500.0), st.floats(0.01, 0.15), st.floats(0.05, 1.0), st.integers(0, 2**32 - 1))
def test_markers_that_reach_far_less_than_their_declared_segment_are_refused(length, share, together, seed):
    """The markers reach at most 0.15 of the declared length plus C's 40 mm (below a quarter of it from 1 m up): read
    as a larger unit than the file says, named with the segment, its declared length and the farthest pair."""
    trial = _trial(share * length, together, seed)
    with pytest.raises(InputError) as info:
        trial.require_usable(["A", "B", "C"], {m: "thigh" for m in "ABC"}, {"thigh": length})
    msg = str(info.value)
    assert "span.trc" in msg and "segment 'thigh'" in msg and f"{length:g} mm long (length_mm)" in msg, msg
    assert "larger unit" in msg and "length_mm" in msg, msg


@settings(max_examples=30, deadline=None)
@given(st.floats(100.0, 2000.0), st.floats(SMALLEST_REACH_SHARE + 0.05, 1.4), st.floats(0.05, 1.0),
       st.integers(0, 2**32 - 1))
def test_markers_that_reach_a_fair_share_of_their_declared_segment_pass(length, share, together, seed):
    _trial(share * length, together, seed).require_usable(["A", "B", "C"], {m: "thigh" for m in "ABC"},
                                                          {"thigh": length})


def test_a_trial_in_centimetres_labelled_mm_is_refused_on_the_bundled_models(tmp_path):
    """The bundled minimal hip and leg simulated, then written with every coordinate divided by 10 under the same
    'mm': refused by identify and fit (exit 2) where they had fitted a hip 10 times too near its markers with exit 0;
    the trials as simulated pass."""
    from pathlib import Path

    from identcheck import api, cli
    from identcheck.io.trc import read_trc, write_trc

    root = Path(__file__).resolve().parents[2] / "examples"
    for name, verb in (("hip_31", "identify"), ("leg", "fit")):
        good, small = tmp_path / f"{name}.trc", tmp_path / f"{name}_cm.trc"
        api.simulate(root / f"{name}.toml", good, seed=3, n_frames=60)
        trial = read_trc(good)
        write_trc(small, trial.xyz / 10.0, trial.labels, trial.rate_hz)          # (in mm, as it says)
        assert cli.main([verb, str(root / f"{name}.toml"), str(small), "--json"]) == 2
        assert cli.main([verb, str(root / f"{name}.toml"), str(good), "--json"]) in (0, 1)


def test_the_reach_is_measured_to_the_segments_near_it_not_to_a_far_head():
    """A whole body in centimetres written as mm: a thigh (declared 420 mm) whose pelvis marker lies 45 "mm" away and a
    head marker 120 "mm" away. Measured to every marker, the head's 120 mm cleared a quarter of 420; measured to the
    segments within two joints of the thigh (the pelvis here), the trial is refused and the pelvis marker named."""
    rng = np.random.default_rng(5)
    thigh = rng.normal(0.0, 5.0, (50, 3))
    xyz = np.stack([thigh, thigh + [45.0, 0.0, 0.0], thigh + [0.0, 0.0, 120.0]], axis=1)
    trial = Trial(xyz, ["T", "P", "H"], 100.0, source="body.trc")
    where = {"T": "thigh", "P": "pelvis", "H": "head"}
    trial.require_usable(["T", "P", "H"], where, {"thigh": 420.0})                  # every marker: the head passes it
    with pytest.raises(InputError) as info:
        trial.require_usable(["T", "P", "H"], where, {"thigh": 420.0}, {"thigh": {"pelvis"}})
    msg = str(info.value)
    assert "segment 'thigh' is declared 420 mm long" in msg and "'T' to 'P'" in msg and "45.0 mm" in msg, msg


@settings(max_examples=40, deadline=None)
@given(st.floats(1.0, 3000.0), st.integers(3, 12), st.integers(0, 2**32 - 1))
def test_a_trial_spanning_less_than_a_limb_is_asked_about_centimetres(span, n_markers, seed):
    """Markers whose frames span `span` mm (the diagonal of their bounding box): a question about centimetres (naming
    the file and the span) from 10 mm, where the readers' question about metres stops, up to 250 mm; nothing from
    there."""
    from identcheck.io.trc import SMALL_SPAN_MM, centimetres_suspected, frame_span

    rng = np.random.default_rng(seed)
    unit = rng.random((1, n_markers, 3)) + rng.normal(0.0, 1e-3, (30, n_markers, 3))
    xyz = unit * (span / frame_span(unit))
    said = centimetres_suspected(xyz, "tiny.trc")
    assert bool(said) == (10.0 <= frame_span(xyz) < SMALL_SPAN_MM), (span, said)
    if said:
        assert said.startswith("tiny.trc:") and f"{frame_span(xyz):.0f} mm" in said and "Units field" in said


def test_a_knee_in_centimetres_labelled_mm_is_warned_about_by_fit_and_diagnose(tmp_path):
    """The bundled knee, its segment lengths taken out of the model (so that nothing refuses the trial), simulated
    and written with every coordinate divided by 10 under the same 'mm': ``fit`` says so in its warnings (kind
    ``units``), ``diagnose`` on standard error; as simulated (a 300 mm span), neither says anything of units."""
    import warnings as pywarnings
    from pathlib import Path

    from identcheck import api
    from identcheck.io.trc import read_trc, write_trc

    model = tmp_path / "knee.toml"
    text = (Path(__file__).resolve().parents[2] / "examples" / "knee_21.toml").read_text()
    model.write_text("\n".join(line for line in text.splitlines() if not line.startswith("length_mm")))
    good, small = tmp_path / "knee.trc", tmp_path / "knee_cm.trc"
    api.simulate(model, good, seed=3, n_frames=300)
    trial = read_trc(good)
    write_trc(small, trial.xyz / 10.0, trial.labels, trial.rate_hz)
    with pywarnings.catch_warnings(record=True) as said:
        pywarnings.simplefilter("always")
        kinds = {w["kind"] for w in api.fit(model, small).to_dict()["warnings"]}
        assert "units" in kinds
        assert "units" not in {w["kind"] for w in api.fit(model, good).to_dict()["warnings"]}
    assert not any("span only" in str(w.message) for w in said)       # (fit puts it in its JSON, not on stderr)
    with pywarnings.catch_warnings(record=True) as said:
        pywarnings.simplefilter("always")
        api.diagnose(model, small)
    assert any("knee_cm.trc" in str(w.message) and "centimetres" in str(w.message) for w in said)


@settings(max_examples=30, deadline=None)
@given(st.floats(150.0, 600.0), st.floats(4.6, 12.0), st.floats(0.05, 1.0), st.integers(0, 2**32 - 1))
def test_markers_spanning_several_times_their_declared_segment_are_refused(length, ratio, together, seed):
    """A segment declared `length` mm long whose markers lie `ratio` times that apart, and over 1 m (coordinates ten
    times too large for their units): refused, naming the segment, its declared length and the span, however little
    the two markers are seen together; declared long enough, the same markers pass."""
    ratio = max(ratio, 1.1 * 1000.0 / length)
    trial = _trial(ratio * length, together, seed)
    where = {m: "thigh" for m in "ABC"}
    with pytest.raises(InputError) as info:
        trial.require_usable(["A", "B", "C"], where, {"thigh": length})
    msg = str(info.value)
    assert "span.trc" in msg and f"segment 'thigh' is declared {length:g} mm long (length_mm)" in msg, msg
    assert "ten times too large" in msg and "length_mm" in msg, msg
    trial.require_usable(["A", "B", "C"], where, {"thigh": ratio * length})


@settings(max_examples=30, deadline=None)
@given(st.floats(150.0, 600.0), st.floats(0.5, 3.5), st.floats(0.05, 1.0), st.integers(0, 2**32 - 1))
def test_markers_spanning_about_their_declared_segment_pass(length, ratio, together, seed):
    _trial(ratio * length, together, seed).require_usable(["A", "B", "C"], {m: "thigh" for m in "ABC"},
                                                          {"thigh": length})


@settings(max_examples=30, deadline=None)
@given(st.floats(20.0, 200.0), st.floats(300.0, 900.0), st.floats(0.05, 1.0), st.integers(0, 2**32 - 1))
def test_a_short_declared_length_does_not_refuse_markers_spread_under_a_metre(length, apart, together, seed):
    """A length given for ``simulate`` short of the segment's marker spread (a pelvis declared 70 mm, its markers on
    both iliac spines 300 mm apart) is no units error: under 1 m apart, the markers pass whatever it declares."""
    _trial(apart, together, seed).require_usable(["A", "B", "C"], {m: "pelvis" for m in "ABC"}, {"pelvis": length})


@settings(max_examples=40, deadline=None)
@given(st.floats(500.0, 2e5), st.integers(3, 12), st.integers(0, 2**32 - 1))
def test_a_model_spanning_more_than_a_body_is_asked_about_its_units(span, n_markers, seed):
    """A model's markers whose frames span `span` mm: a question about coordinates ten times too large (naming the file
    and the span in metres) beyond 5 m, up to the 100 km where the readers refuse a units field outright; nothing
    below."""
    from identcheck.io.trc import BODY_SPAN_MM, LARGE_SPAN_MM, frame_span, scaled_up_suspected

    rng = np.random.default_rng(seed)
    unit = rng.random((1, n_markers, 3)) + rng.normal(0.0, 1e-3, (30, n_markers, 3))
    xyz = unit * (span / frame_span(unit))
    said = scaled_up_suspected(xyz, "huge.trc")
    assert bool(said) == (LARGE_SPAN_MM < frame_span(xyz) <= BODY_SPAN_MM[1]), (span, said)
    if said:
        assert said.startswith("huge.trc:") and f"{frame_span(xyz) / 1e3:.3g} m" in said and "ten times" in said


def test_a_leg_ten_times_too_large_is_warned_about_by_fit_and_diagnose_and_refused_by_its_lengths(tmp_path):
    """The bundled leg simulated and written with every coordinate scaled up under the same 'mm', as far as keeps every
    segment within the 3 m no segment exceeds (the leg then spans over 5 m): with its segments' lengths taken out of
    the model, ``fit`` and ``diagnose`` both answer and say so in their JSON warnings (kind ``units``), where nothing
    had been said (times 10: hip distances of 1.3-1.5 m, exit 1; ``diagnose`` exit 0); with the lengths declared,
    the trial is refused (exit 2) naming a segment and its length; as simulated, nothing is said."""
    from pathlib import Path

    import warnings as pywarnings

    from identcheck import api, cli
    from identcheck.io.model import Model
    from identcheck.io.trc import LARGE_SPAN_MM, frame_span, read_trc, write_trc

    root = Path(__file__).resolve().parents[2] / "examples"
    model = tmp_path / "leg.toml"
    text = (root / "leg.toml").read_text()
    model.write_text("\n".join(line for line in text.splitlines() if not line.startswith("length_mm")))
    good, large = tmp_path / "leg.trc", tmp_path / "leg_x10.trc"
    api.simulate(root / "leg.toml", good, seed=3, n_frames=120)
    trial = read_trc(good)
    segments = Model.from_toml(model).segments.values()
    index = {lab: i for i, lab in enumerate(trial.labels)}
    widest = max(np.nanmax(np.linalg.norm(trial.xyz[:, [index[m] for m in s.markers]][:, :, None]
                                          - trial.xyz[:, [index[m] for m in s.markers]][:, None], axis=3))
                 for s in segments)
    factor = 0.95 * LONGEST_SEGMENT_MM / widest
    assert factor * frame_span(trial.xyz) > LARGE_SPAN_MM                       # (the leg spans over 5 m)
    write_trc(large, trial.xyz * factor, trial.labels, trial.rate_hz)
    said = lambda doc: [w["message"] for w in doc["warnings"] if w["kind"] == "units"]       # noqa: E731
    assert any("ten times too large" in m and "leg_x10.trc" in m for m in said(api.fit(model, large).to_dict()))
    with pywarnings.catch_warnings():
        pywarnings.simplefilter("ignore")             # (a batch run's filters: the JSON keeps what they hide)
        assert any("ten times too large" in m for m in said(api.diagnose(model, large).to_dict()))
    assert not said(api.fit(model, good).to_dict())
    with pytest.raises(InputError) as info:
        api.fit(root / "leg.toml", large)
    assert "declared" in str(info.value) and "length_mm" in str(info.value) and "leg_x10.trc" in str(info.value)
    assert cli.main(["fit", str(root / "leg.toml"), str(large), "--json"]) == 2


@settings(max_examples=30, deadline=None)
@given(st.integers(4, 12), st.integers(0, 2**32 - 1), st.data())
def test_most_pairs_within_a_millimetre_are_one_units_message_and_one_pair_is_a_label(n, seed, data):
    """`n` markers of a body in metres written as mm, `far` of them placed away (a stray marker in mm): while half the
    pairs or more lie within a millimetre, one message about units and none about two labels (43 of 45 such pairs had
    been listed one by one as a marker exported under two labels); a marker in mm exported under two labels, or under
    most of them, is named as such, units never mentioned."""
    rng = np.random.default_rng(seed)
    body = rng.normal(0.0, 200.0, (1, n, 3)) + rng.normal(0.0, 0.5, (40, n, 3)) + rng.normal(0.0, 300.0, (40, 1, 3))
    labels = [f"M{i}" for i in range(n)]
    far = data.draw(st.integers(0, n), label="markers far")
    tiny = body / 1000.0
    tiny[:, :far] += np.arange(1, far + 1)[None, :, None] * 50.0
    near = n - far
    pairs = near * (near - 1) // 2
    trial = Trial(tiny, labels, 100.0, source="metres.trc")
    if 2 * pairs >= n * (n - 1) // 2:
        with pytest.raises(InputError) as info:
            trial.require_usable(labels)
        msg = str(info.value)
        assert "metres in a file that says mm" in msg and "two labels" not in msg, msg
    for k in (2, n // 2 + 1):                         # one marker in mm exported under k labels, even most of them
        twice = body.copy()
        twice[:, 1:k] = twice[:, :1] + rng.normal(0.0, 0.05, (40, k - 1, 3))
        with pytest.raises(InputError) as info:
            Trial(twice, labels, 100.0, source="mm.trc").require_usable(labels)
        msg = str(info.value)
        assert "'M0'" in msg and "'M1'" in msg and "two labels" in msg and "metres" not in msg, msg


def test_millimetres_labelled_cm_are_one_units_question_in_both_verbs(tmp_path):
    """The bundled leg written in mm under a 'cm' units field (scaled so that no segment, read as cm, exceeds 3 m):
    the reader asks whether the coordinates are in mm (its span over 5 m), and the model's span is not asked again:
    one `units` warning in ``fit``'s JSON and in ``diagnose``'s, where both had carried two."""
    from pathlib import Path

    from identcheck import api
    from identcheck.io.model import Model
    from identcheck.io.trc import LARGE_SPAN_MM, frame_span, read_trc, write_trc

    root = Path(__file__).resolve().parents[2] / "examples"
    model = tmp_path / "leg.toml"
    model.write_text("\n".join(line for line in (root / "leg.toml").read_text().splitlines()
                               if not line.startswith("length_mm")))
    good, labelled = tmp_path / "leg.trc", tmp_path / "leg_cm.trc"
    api.simulate(root / "leg.toml", good, seed=5, n_frames=120)
    trial = read_trc(good)
    index = {lab: i for i, lab in enumerate(trial.labels)}
    widest = max(np.nanmax(np.linalg.norm(trial.xyz[:, [index[m] for m in s.markers]][:, :, None]
                                          - trial.xyz[:, [index[m] for m in s.markers]][:, None], axis=3))
                 for s in Model.from_toml(model).segments.values())
    factor = 0.95 * LONGEST_SEGMENT_MM / widest          # read as cm, every segment within the 3 m none exceeds
    assert factor * frame_span(trial.xyz) > LARGE_SPAN_MM
    write_trc(labelled, trial.xyz * factor / 10.0, trial.labels, trial.rate_hz)
    text = labelled.read_text().splitlines()
    head = text[2].split("\t")
    head[4] = "cm"                                                      # the Units field of line 3
    labelled.write_text("\n".join(text[:2] + ["\t".join(head)] + text[3:]) + "\n")
    for verb in (api.fit, api.diagnose):
        units = [w["message"] for w in verb(model, labelled).to_dict()["warnings"] if w["kind"] == "units"]
        assert len(units) == 1 and "says cm" in units[0], units
