"""Input and output: the TOML model, and TRC / C3D marker trajectories.

All input checks live here. Readers return plain arrays in millimetres with NaN for
occluded samples; :class:`identcheck.trial.Trial` wraps them.

The names below are loaded on first use (PEP 562): importing the package, or only its model reader, does not
import NumPy, so a verb that reads no trajectories (``plan``) starts without it.
"""
from __future__ import annotations

import importlib

_WHERE = {"read_c3d": "c3d", "write_c3d": "c3d",
          "JOINT_TYPES": "model", "Joint": "model", "Model": "model", "Segment": "model",
          "MarkerData": "trc", "read_trc": "trc", "write_trc": "trc"}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(f"identcheck.io.{_WHERE[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'identcheck.io' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_WHERE))
