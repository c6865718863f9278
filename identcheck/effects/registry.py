"""The library of named effects (names from the contract), each a detector plus a model augmentation."""
from identcheck.effects.base import Effect, Proposal
from identcheck.effects.extra_dof import ExtraDof
from identcheck.effects.joint_translation import JointTranslation
from identcheck.effects.marker_slip import MarkerSlip
from identcheck.effects.marker_swap import MarkerSwap
from identcheck.effects.outliers import Outliers
from identcheck.effects.soft_tissue import SoftTissue
from identcheck.effects.spatial_distortion import SpatialDistortion
from identcheck.effects.time_offset import TimeOffset

EFFECTS = (SoftTissue(), MarkerSlip(), MarkerSwap(), JointTranslation(), ExtraDof(), TimeOffset(),
           Outliers(), SpatialDistortion())
"""Every effect, in the contract's order."""
NAMES = tuple(e.name for e in EFFECTS)

__all__ = ["Effect", "Proposal", "EFFECTS", "NAMES"]
