"""The exact certificate that a marker beyond the one-point segment rejects revolute (2,1)'s other joints."""
import random
from fractions import Fraction

import pytest
from hypothesis import given, settings, strategies as st

from identcheck.certify import twin as T


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10**6), st.sampled_from(["spherical", "revolute"]))
def test_random_subjects_are_certified(seed, far_joint):
    """For random rational subjects and motions: the true joint keeps the far marker on a sphere (det 0 over
    Q); its mirror and all 32 conjugates of the second joint keep B fixed in their frame (genuine joints)
    and put the far marker off every sphere."""
    c = T.certify(seed, far_joint)
    assert c["truth_determinant_zero"] and c["mirror_explains_B"] and c["mirror_rejected"]
    assert c["conjugates"] == 32 and c["conjugates_explain_B"] and c["conjugates_rejected"] == 32
    assert c["certified"]


@pytest.mark.parametrize("seed", range(5))
def test_the_checks_can_fail(seed):
    """Negative controls: B itself, fixed in every candidate's frame, is on a sphere for every candidate
    (nothing to reject); a joint that is not a candidate (d moved by 1 mm) does not explain B."""
    sub = T.subject(random.Random(seed))
    J = sub["joint"]
    B, F = T.data(sub)
    one = Fraction(1)
    mirror = dict(J, c=-J["c"], l=-J["l"])
    for cand in (J, mirror):
        assert not T._off_every_sphere(T.far_marker_in_segment(cand, B, B, one))
    assert not T._off_every_sphere(T.far_marker_in_segment(J, B, F, one))          # the truth survives
    wrong = dict(J, d=J["d"] + 1)
    try:
        pts = T.far_marker_in_segment(wrong, B, B, one)
    except ValueError:
        return
    assert not T._fixed(pts)
