"""The library's verbs: one function per CLI verb, each taking plain arguments and returning a result.

The command line (:mod:`identcheck.cli`) parses its arguments, calls exactly one of these, renders the
result and chooses the exit code; nothing a verb computes lives in the CLI.
"""
from __future__ import annotations

from pathlib import Path

from identcheck.effects.inject import SEED_OFFSET, inject_effect
from identcheck.errors import InputError
from identcheck.io.model import Model
from identcheck.simulate.rigid import Simulation, simulate
from identcheck.trial import FORMATS


def simulate_file(model_path, out_path, seed: int = 0, effect: str | None = None,
                  effect_seed: int | None = None, **kw) -> Simulation:
    """Load a model, simulate it, inject `effect` if given, and write the (noisy) trial as
    TRC or C3D by extension.

    Parameters
    ----------
    model_path : str or os.PathLike
        TOML model file.
    out_path : str or os.PathLike
        ``.trc`` or ``.c3d`` (any case).
    seed : int
    effect : str, optional
        An effect name of :data:`identcheck.effects.inject.EFFECTS`, injected before writing.
    effect_seed : int, optional
        Seed of the effect's draw; default ``seed + effects_inject.SEED_OFFSET``.
    **kw
        Passed to :func:`identcheck.simulate.rigid.simulate`.

    Returns
    -------
    Simulation

    Raises
    ------
    InputError
        Bad model, bad arguments, an unknown output extension (checked before simulating),
        or an effect the model cannot carry.
    """
    out_path = Path(out_path)
    if out_path.suffix.lower() not in FORMATS:
        raise InputError([f"unknown trial file extension {out_path.suffix or '(none)'!r} (expected "
                          f"one of {', '.join(FORMATS)})"], source=str(out_path))
    sim = simulate(Model.from_toml(model_path), seed=seed, **kw)
    if effect is not None:
        sim = inject_effect(sim, effect, seed=seed + SEED_OFFSET if effect_seed is None else effect_seed)
    sim.trial.to_file(out_path)
    return sim
