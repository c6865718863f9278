"""A model segment without markers that no joint points pose: ``diagnose`` fits every segment at once and cannot
start, so the model is refused (exit 2) by that segment's field, saying what to do: not degenerate data of the
trial, as it had read."""
from __future__ import annotations

from identcheck import cli


def test_a_markerless_segment_is_named_as_the_models(tmp_path, capsys, examples):
    model = tmp_path / "leg_bare_foot.toml"
    text = (examples / "leg.toml").read_text().replace('markers = ["RHEE", "RTOE"]', "markers = []")
    assert text != (examples / "leg.toml").read_text()
    model.write_text(text)
    trial = tmp_path / "t.c3d"
    assert cli.main(["simulate", str(model), "--out", str(trial), "--frames", "200", "--noise-mm", "0.3"]) == 0
    capsys.readouterr()
    assert cli.main(["diagnose", str(model), str(trial), "--json"]) == 2       # the model is bad input for diagnose
    out = capsys.readouterr()
    assert "leg_bare_foot.toml" in out.err and "segments.foot_r.markers: none" in out.err
    assert "give it markers" in out.err and "Traceback" not in out.err and "t.c3d" not in out.err
