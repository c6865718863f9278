"""Effects name their frames as the capture software numbers them: a swap found in a file whose frames start at
501 is reported at rows `frames` and at file frames `file_frames` = rows + 501, in the JSON and the text."""
from __future__ import annotations

import json
from pathlib import Path

from identcheck import cli
from identcheck.io.trc import write_trc
import identcheck as ic

ROOT = Path(__file__).resolve().parents[2]


def test_a_swap_is_reported_in_the_files_own_frame_numbers(tmp_path, capsys):
    model = str(ROOT / "examples" / "diagnose_leg.toml")
    trial = tmp_path / "swap.trc"
    assert cli.main(["simulate", model, "--out", str(trial), "--seed", "3", "--noise-mm", "0.3", "--frames", "400",
                     "--effect", "marker_swap"]) == 0
    t = ic.read_trial(trial)
    shifted = tmp_path / "from_501.trc"
    write_trc(shifted, t.as_array(), t.labels, t.rate_hz, first_frame=501)
    capsys.readouterr()
    cli.main(["diagnose", model, str(shifted), "--json"])
    doc = json.loads(capsys.readouterr().out)
    swaps = [e for e in doc["effects"] if e["name"] == "marker_swap"]
    assert swaps, [e["name"] for e in doc["effects"]]
    where = swaps[0]["where"]
    assert where["file_frames"] == [f + 501 for f in where["frames"]]
    cli.main(["diagnose", model, str(shifted)])
    assert str(where["file_frames"]) in capsys.readouterr().out
