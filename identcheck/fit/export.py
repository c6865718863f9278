"""The fitted joints as virtual markers beside the measured ones (``--export-markers OUT.trc|OUT.c3d``), so
that a lab can take them into OpenSim, biobuddy or its own C3D pipeline.

Each ball joint adds ``JOINT.centre``; each hinge adds ``JOINT.axis0`` (the point of its axis nearest the
centre the fit carries in the parent) and ``JOINT.axis1``, :data:`~identcheck.estimate.joint.AXIS_HANDLE_MM`
further along the axis. Their trajectories come from the whole-tree fit (each segment's fitted pose in every
frame), in the trial's units (mm) and frame numbering; a frame in which no marker was seen is left empty.
"""
from __future__ import annotations

import numpy as np

from identcheck.bundle.model import forward
from identcheck.estimate.joint import AXIS_HANDLE_MM
from identcheck.io.model import virtual_names
from identcheck.trial import Trial



def joint_trajectories(fit) -> dict:
    """name -> (F, 3) world trajectory of every joint's virtual markers, from a whole-chain fit."""
    chain = fit.chain
    R, _, centre, _ = forward(chain, fit.terms, fit.state)
    out = {}
    for j in chain.joints:
        if chain.types[j] == "spherical":
            points = [centre[j]]
        else:
            axis = np.einsum("fij,j->fi", R[chain.parent[j]], fit.state.axis[j])
            points = [centre[j], centre[j] + AXIS_HANDLE_MM * axis]
        out.update(zip(virtual_names(j, chain.types[j]), points))
    return out


def export_markers(path, trial: Trial, fit, offset=(0.0, 0.0, 0.0)) -> Trial:
    """Write `trial`'s markers plus the fitted joints' virtual markers to `path` (TRC or C3D by extension);
    returns the trial written. `offset`: what the fitted trial was moved by (:meth:`Trial.recentred`), added
    back to the joints' trajectories."""
    data = trial.as_array()
    seen = np.all(np.isfinite(data), axis=2).any(axis=1)
    extra = joint_trajectories(fit)
    cols = []
    for name, xyz in extra.items():
        xyz = np.array(xyz, dtype=float) + np.asarray(offset, dtype=float)
        xyz[~seen] = np.nan
        cols.append(xyz[:, None, :])
    out = trial.replace(xyz=np.concatenate([data] + cols, axis=1), labels=trial.labels + tuple(extra))
    out.to_file(path)
    return out
