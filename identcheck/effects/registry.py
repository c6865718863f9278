"""The one registry of named effects (the names of docs/contract.md), in the contract's order.

Everything that needs the list reads it here: the simulator's ``--effect`` (:func:`inject_effect`),
``diagnose``'s selection loop, the CLI's choices and the tests. Each effect is one module in this package
holding its injection, its detector, its augmentation and its evidence.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from identcheck.effects.base import Effect, Proposal
from identcheck.effects.extra_dof import ExtraDof
from identcheck.effects.injection import (SEED_OFFSET, SOURCE, apply_change, extra_rotation_world, rotate, rotations,
                                          subtree)
from identcheck.effects.joint_translation import JointTranslation
from identcheck.effects.marker_slip import MarkerSlip
from identcheck.effects.marker_swap import MarkerSwap
from identcheck.effects.outliers import Outliers
from identcheck.effects.soft_tissue import SoftTissue
from identcheck.effects.spatial_distortion import SpatialDistortion
from identcheck.effects.time_offset import TimeOffset
from identcheck.errors import InputError

if TYPE_CHECKING:  # pragma: no cover
    from identcheck.simulate.rigid import Simulation

EFFECTS: dict = {e.name: e for e in (SoftTissue(), MarkerSlip(), MarkerSwap(), JointTranslation(), ExtraDof(),
                                     TimeOffset(), Outliers(), SpatialDistortion())}
"""Effect name -> the effect, in the contract's order."""
NAMES = tuple(EFFECTS)

__all__ = ["Effect", "Proposal", "EFFECTS", "NAMES", "SEED_OFFSET", "inject_effect", "true_centre_world"]


def inject_effect(sim: "Simulation", name: str, seed: int = 0) -> "Simulation":
    """A new simulation whose trial carries the effect `name`, drawn from `seed`.

    Parameters
    ----------
    sim : Simulation
        A rigid simulation (from :func:`~identcheck.simulate.rigid.simulate`); it is not modified.
    name : str
        One of :data:`NAMES`.
    seed : int
        Seeds the draw of the effect's place, timing and magnitude.

    Returns
    -------
    Simulation
        ``trial`` and ``clean`` carry the effect, ``truth`` is unchanged, ``settings["effect"]``
        records it.

    Raises
    ------
    InputError
        Unknown effect name, a simulation that already carries one, or an effect the model
        cannot carry (e.g. ``extra_dof`` without a revolute joint).
    """
    if name not in EFFECTS:
        raise InputError([f"unknown effect {name!r} (valid effects: {', '.join(NAMES)})"], source=SOURCE)
    if "effect" in sim.settings:
        raise InputError([f"the simulation already carries effect {sim.settings['effect']['name']!r}; "
                          "inject one effect per simulation"], source=SOURCE)
    change = EFFECTS[name].inject(sim, np.random.default_rng(seed))
    return apply_change(sim, name, seed, change)




def true_centre_world(sim: "Simulation", joint: str) -> np.ndarray:
    """True centre of `joint` in the world, shape (n_frames, 3), mm, including the effect.

    ``joint_translation`` moves its joint's centre and every centre below it; ``extra_dof``
    rotates the centres below its joint about that joint's centre; other effects leave the
    centres of the rigid truth (a delayed segment lags its markers, not the skeleton).
    """
    if joint not in sim.truth.joints:
        raise InputError([f"unknown joint {joint!r} (the model has: {', '.join(sim.truth.joints)})"],
                         source=SOURCE)
    centre = sim.truth.centre_world(joint)
    effect = sim.settings.get("effect") or {}
    if effect.get("name") not in ("joint_translation", "extra_dof"):
        return centre
    moved = effect["where"]["joint"]
    below = subtree(sim.model, sim.model.joints[moved].child)
    rot_p = rotations(sim, sim.model.joints[moved].parent)
    if effect["name"] == "joint_translation":
        if joint == moved or sim.model.joints[joint].parent in below:
            centre = centre + rotate(rot_p, np.asarray(effect["params"]["translation_parent"]))
        return centre
    if sim.model.joints[joint].parent not in below:
        return centre
    turn = extra_rotation_world(rot_p, effect["params"]["axis_parent"], effect["params"]["angle_deg"])
    pivot = sim.truth.centre_world(moved)
    return pivot + rotate(turn, centre - pivot)
