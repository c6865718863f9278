"""Values made JSON-plain: numpy arrays and scalars become lists, floats and ints, so that every
result can be written with the standard ``json`` module and nothing is hidden by ``default=str``."""
from __future__ import annotations

import numpy as np


def plain(value):
    """`value` with numpy arrays and scalars turned into lists, floats and ints (for JSON)."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value
