"""The library of named effects (names from the contract), each a detector plus a model augmentation."""
from .base import Effect, Proposal
from .extra_dof import ExtraDof
from .joint_translation import JointTranslation
from .marker_slip import MarkerSlip
from .marker_swap import MarkerSwap
from .outliers import Outliers
from .soft_tissue import SoftTissue
from .spatial_distortion import SpatialDistortion
from .time_offset import TimeOffset

EFFECTS = (SoftTissue(), MarkerSlip(), MarkerSwap(), JointTranslation(), ExtraDof(), TimeOffset(),
           Outliers(), SpatialDistortion())
"""Every effect, in the contract's order."""
NAMES = tuple(e.name for e in EFFECTS)

__all__ = ["Effect", "Proposal", "EFFECTS", "NAMES"]
