"""Input and output: the TOML model, and TRC / C3D marker trajectories.

All input checks live here. Readers return plain arrays in millimetres with NaN for
occluded samples; :class:`identcheck.trial.Trial` wraps them.
"""
from identcheck.io.c3d import read_c3d, write_c3d
from identcheck.io.model import JOINT_TYPES, Joint, Model, Segment
from identcheck.io.trc import MarkerData, read_trc, write_trc

__all__ = ["JOINT_TYPES", "Joint", "MarkerData", "Model", "Segment", "read_c3d", "read_trc",
           "write_c3d", "write_trc"]
