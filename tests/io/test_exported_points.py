"""A file ``--export-markers`` wrote (measured markers plus each joint's centre or hinge-axis points, named
``JOINT.centre``, ``JOINT.axis0``, ``JOINT.axis1``) is a fit's output: ``fit``, ``diagnose`` and ``skeleton`` all
refuse it as a trial, naming the points (``diagnose`` had fitted it as measured and named no effect; ``skeleton``
had grouped the joint points as markers)."""
from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from identcheck import api
from identcheck.errors import InputError
from identcheck.infer.workflow import exported_joints

LEG = Path(__file__).resolve().parents[2] / "examples" / "leg.toml"


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("exported")
    api.simulate(LEG, folder / "leg.trc", seed=4, noise_mm=0.3)
    api.fit(LEG, folder / "leg.trc", export_markers=folder / "exported.trc")
    return folder / "exported.trc"


@pytest.mark.parametrize("verb", ["fit", "diagnose", "skeleton"])
def test_an_exported_file_is_refused_as_a_trial(exported, verb, tmp_path):
    call = {"fit": lambda: api.fit(LEG, exported), "diagnose": lambda: api.diagnose(LEG, exported),
            "skeleton": lambda: api.skeleton(exported, tmp_path / "model.toml")}[verb]
    with pytest.raises(InputError, match=r"hip_r\.centre.*virtual marker of joint 'hip_r'"):
        call()


@settings(max_examples=50, deadline=None)
@given(st.lists(st.text(alphabet="abRL_1", min_size=1, max_size=5), min_size=1, max_size=6, unique=True),
       st.lists(st.sampled_from(["centre", "axis0", "axis1", "both axes"]), min_size=1, max_size=4))
def test_joints_are_read_from_their_points_names(markers, kinds):
    labels, want = list(markers), set()
    for k, kind in enumerate(kinds):
        joint = f"j{k}"
        if kind == "both axes":
            labels += [f"{joint}.axis0", f"{joint}.axis1"]
            want.add(joint)
        else:
            labels.append(f"{joint}.{kind}")
            if kind == "centre":
                want.add(joint)
    assert set(exported_joints(labels)) == want
