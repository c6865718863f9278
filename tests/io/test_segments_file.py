"""The ``--segments FILE`` reader (identcheck.io.segments): both forms, and every problem at once."""
import pytest

from identcheck.errors import InputError
from identcheck.io.segments import read_segments


def test_short_form_keeps_names_and_order(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('[segments]\npelvis = ["RASI", "LASI", "SACR"]\n"thigh r" = ["RGT", "RTHI"]\n')
    assert read_segments(p) == {"pelvis": ("RASI", "LASI", "SACR"), "thigh r": ("RGT", "RTHI")}


def test_a_model_file_is_read_for_its_segments(examples):
    segs = read_segments(examples / "real_walking2_legs.toml")
    assert segs["pelvis"] == ("RASI", "LASI", "RPSI", "LPSI") and len(segs) == 5


def test_every_problem_at_once(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('colour = 1\n[segments]\na = ["M1", "M2"]\nb = ["M2", ""]\nc = []\n')
    with pytest.raises(InputError) as exc:
        read_segments(p)
    msg = str(exc.value)
    assert "s.toml" in msg and "colour: unknown key" in msg and "segments.b" in msg and "segments.c: no markers" in msg


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_segments(tmp_path / "none.toml")
