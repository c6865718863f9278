"""The held-out effects generator's v2 draws pass their own independent checker (gaps, layouts, sit-to-stand, the new
shapes), and the checker is not a rubber stamp: a gap filled back in on one trial makes it fail."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow      # the fast lane (pytest -m 'not slow') leaves these out

HERE = Path(__file__).resolve().parents[2] / "benchmarks" / "heldout_effects"


def _run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, timeout=600)


def test_a_small_v2_draw_passes_its_checker_and_a_filled_gap_fails_it(tmp_path):
    out = tmp_path / "v2"
    assert _run(HERE / "generator.py", "--out", out, "--n", "12", "--seed", "5", "--version", "2").returncode == 0
    index = json.loads((out / "index.json").read_text())
    assert index["version"] == 2 and len(index["trials"]) == 12
    ok = _run(HERE / "check.py", out)
    assert ok.returncode == 0, ok.stdout[-2000:]
    gapped = next(t for t in index["trials"] if t["category"]["gaps"])
    trc = out / f"{gapped['stem']}.trc"
    lines = trc.read_text().split("\n")
    for i, line in enumerate(lines[5:], start=5):          # the first data row with an empty cell: fill it
        cells = line.split("\t")
        if "" in cells[2:]:
            cells = [c if c != "" else "0.0" for c in cells]
            lines[i] = "\t".join(cells)
            break
    else:
        pytest.fail("a trial with gaps wrote no empty cell")
    trc.write_text("\n".join(lines))
    bad = _run(HERE / "check.py", out)
    assert bad.returncode == 1 and gapped["stem"] in bad.stdout
