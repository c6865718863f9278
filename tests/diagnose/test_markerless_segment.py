"""A model segment without markers that no joint points pose: ``diagnose`` fits every segment at once and cannot
start, so it says what in the model stops it (the segment, and what to do), not a fault of the trial."""
from __future__ import annotations

import json

from identcheck import cli


def test_a_markerless_segment_is_named_as_the_models(tmp_path, capsys, examples):
    model = tmp_path / "leg_bare_foot.toml"
    text = (examples / "leg.toml").read_text().replace('markers = ["RHEE", "RTOE"]', "markers = []")
    assert text != (examples / "leg.toml").read_text()
    model.write_text(text)
    trial = tmp_path / "t.c3d"
    assert cli.main(["simulate", str(model), "--out", str(trial), "--frames", "200", "--noise-mm", "0.3"]) == 0
    capsys.readouterr()
    assert cli.main(["diagnose", str(model), str(trial), "--json"]) == 1
    out = capsys.readouterr()
    why = json.loads(out.out)["degenerate"]
    assert "leg_bare_foot.toml" in why and "'foot_r' has no markers" in why and "give it markers" in why
    assert "Traceback" not in out.err
