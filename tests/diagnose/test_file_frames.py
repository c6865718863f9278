"""Effects name their frames as the capture software numbers them: a swap found in a file whose frames start at
501 is reported at rows `frames` and at file frames `file_frames` = rows + 501, in the JSON and the text."""
from __future__ import annotations

import json
from pathlib import Path

from identcheck import cli
from identcheck.io.trc import write_trc
import identcheck as ic

ROOT = Path(__file__).resolve().parents[2]


MODEL = str(ROOT / "examples" / "diagnose_leg.toml")


def _swap_from_501(tmp_path):
    """A simulated swap (400 frames), written again with its frames numbered from 501: (the trial, its path)."""
    trial = tmp_path / "swap.trc"
    assert cli.main(["simulate", MODEL, "--out", str(trial), "--seed", "3", "--noise-mm", "0.3", "--frames", "400",
                     "--effect", "marker_swap"]) == 0
    t = ic.read_trial(trial)
    shifted = tmp_path / "from_501.trc"
    write_trc(shifted, t.as_array(), t.labels, t.rate_hz, first_frame=501)
    return t, shifted


def test_a_swap_is_reported_in_the_files_own_frame_numbers(tmp_path, capsys):
    model = MODEL
    _, shifted = _swap_from_501(tmp_path)
    capsys.readouterr()
    cli.main(["diagnose", model, str(shifted), "--json"])
    doc = json.loads(capsys.readouterr().out)
    swaps = [e for e in doc["effects"] if e["name"] == "marker_swap"]
    assert swaps, [e["name"] for e in doc["effects"]]
    where = swaps[0]["where"]
    assert where["file_frames"] == [f + 501 for f in where["frames"]]
    cli.main(["diagnose", model, str(shifted)])
    assert str(where["file_frames"]) in capsys.readouterr().out


def test_the_evidence_figure_and_residual_map_draw_frames_in_the_files_numbering(tmp_path):
    """The same trial starting at file frame 501: the swap's evidence is drawn from frame 501 on, its span where
    the JSON's file_frames put it, its title names the file's frame, and the residual map's frame axis starts at
    501 too."""
    t, shifted = _swap_from_501(tmp_path)
    diag = ic.diagnose(MODEL, shifted)
    from identcheck.report.diagnose_figures import FRAME_LABEL, evidence_figure, residual_map

    k = next(i for i, s in enumerate(diag.steps) if s.name == "marker_swap")
    step, where = diag.steps[k], diag.to_dict()["effects"][k]["where"]
    ax = evidence_figure(step, diag.first_frame, diag.numbered(step.where)).axes[0]
    x = ax.lines[0].get_xdata()
    assert x[0] == 501 and x[-1] == 501 + t.n_frames - 1 and ax.get_xlabel() == FRAME_LABEL
    lo, hi = where["file_frames"]
    patch = ax.patches[0]                                       # the swapped span
    xs = [patch.get_x(), patch.get_x() + patch.get_width()] if hasattr(patch, "get_width") else \
        [p[0] for p in patch.get_xy()]
    assert min(xs) == lo and max(xs) == hi
    fig_path = residual_map(diag, tmp_path / "r.png")
    assert fig_path.exists()
