"""The fuzz suite's corpus and its one way of running the CLI.

The corpus is made once per session from the bundled examples: a 200-frame trial of examples/leg.toml (TRC and
C3D, 0.3 mm noise), the knee of examples/knee_21.toml for ``identify``, and a trial of examples/diagnose_leg.toml
for ``diagnose``. Every malformed or valid variant a test builds is derived from these.

``run`` calls :func:`identcheck.cli.main` in-process and checks what every case must hold, whatever its input:
no Python traceback on stderr, never exit 3 (an internal error), and every input file byte for byte unchanged.
"""
from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest

from identcheck import cli
from identcheck.io.trc import read_trc

from fuzz_support import DIAGNOSE_LEG, KNEE, LEG, Outcome, digest


@pytest.fixture
def run(capsys):
    """``run(argv, inputs=())``: the CLI in-process on `argv`; fails the test on a traceback, an exit 3, or an
    input of `inputs` (default: every argument that is an existing file) changed by the run."""

    def call(argv, inputs=None) -> Outcome:
        argv = [str(a) for a in argv]
        files = [Path(a) for a in argv if Path(a).is_file()] if inputs is None else [Path(p) for p in inputs]
        before = {p: digest(p) for p in files}
        capsys.readouterr()
        code = cli.main(argv)
        out, err = capsys.readouterr()
        assert "Traceback" not in err, f"identcheck {' '.join(argv)}:\n{err}"
        assert code != 3, f"internal error on identcheck {' '.join(argv)}:\n{err}"
        changed = [str(p) for p in files if digest(p) != before[p]]
        assert not changed, f"inputs changed by identcheck {' '.join(argv)}: {changed}"
        return Outcome(code, out, err)

    return call


def _simulate(model: Path, out: Path, frames: int, seed: int) -> None:
    assert cli.main(["simulate", str(model), "--out", str(out), "--frames", str(frames), "--noise-mm", "0.3",
                     "--seed", str(seed)]) == 0


@pytest.fixture(scope="session")
def corpus(tmp_path_factory) -> Path:
    """A folder with the reference trials: leg.trc / leg.c3d (examples/leg.toml, 200 frames), knee.trc
    (examples/knee_21.toml, 100 frames) and dleg.trc (examples/diagnose_leg.toml, 200 frames)."""
    folder = tmp_path_factory.mktemp("corpus")
    _simulate(LEG, folder / "leg.trc", 200, 1)
    _simulate(LEG, folder / "leg.c3d", 200, 1)
    _simulate(KNEE, folder / "knee.trc", 100, 2)
    _simulate(DIAGNOSE_LEG, folder / "dleg.trc", 200, 3)
    return folder


@pytest.fixture(scope="session")
def leg_fit(corpus) -> dict:
    """``identcheck fit examples/leg.toml leg.trc --json`` of the reference trial: the numbers every valid
    variant of it must give again."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer), contextlib.redirect_stderr(io.StringIO()):
        code = cli.main(["fit", str(LEG), str(corpus / "leg.trc"), "--json"])
    assert code == 0
    return json.loads(buffer.getvalue())


@pytest.fixture(scope="session")
def leg_markers(corpus):
    """The reference TRC trial as read: (xyz mm, labels, rate)."""
    data = read_trc(corpus / "leg.trc")
    return data.xyz, data.labels, data.rate_hz

