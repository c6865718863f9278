"""The backward check never drops an effect without which a later one, applied again, stops being what it claims: a
knee's second rotation that takes up the skin motion a dropped effect had modelled, beyond any play, keeps that
effect (the forward search would not adopt the rotation there)."""
from __future__ import annotations

from hypothesis import given, strategies as st

from identcheck.diagnose.backward import Adopted, redundant
from identcheck.effects.base import Proposal
from identcheck.effects.extra_dof import MAX_PLAY_DEG, ExtraDof


class _Hyp:
    """A stand-in hypothesis: the check only refits it."""

    def polish(self, max_iter: int = 0) -> "_Hyp":
        return self


class _Earlier:
    name = "soft_tissue"

    def implausible(self, proposal) -> str:
        return ""


class _Rotation(ExtraDof):
    """A second rotation whose refit without the earlier effect ranges over ``payload["range_without"]``."""

    def apply(self, ctx, hyp, proposal):
        proposal.where["range_deg"] = proposal.payload["range_without"]
        return _Hyp()


@given(range_without=st.floats(0.0, 360.0), gain=st.floats(-100.0, 100.0))
def test_an_effect_is_kept_when_a_later_one_without_it_is_implausible(range_without, gain):
    earlier = Adopted(_Earlier(), Proposal("soft_tissue", {"markers": ["RTIB"]}, 1.0, {}))
    later = Adopted(_Rotation(), Proposal("extra_dof", {"joint": "knee", "range_deg": 12.0}, 1.0,
                                          {"range_without": range_without}))
    found = redundant(None, [_Hyp(), _Hyp(), _Hyp()], [earlier, later], lambda without, a: (gain, False), 0)
    if range_without > MAX_PLAY_DEG:
        assert found is None                                  # the earlier effect is kept
    else:
        assert found is not None and found.index == 0 and found.gain == gain
    assert later.proposal.where["range_deg"] == 12.0          # the adopted proposal itself is left as it was
