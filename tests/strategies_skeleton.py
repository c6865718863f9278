"""Hypothesis strategies for ``identcheck skeleton``: random trees of segments, joint types and motions, simulated
by :mod:`identcheck.simulate.rigid`, with optional soft-tissue wobble, occlusions and a loose marker."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from hypothesis import strategies as st

from identcheck.io.model import Model
from identcheck.simulate.rigid import simulate
from identcheck.trial import Trial


@dataclass
class Case:
    """A simulated trial and the skeleton it came from."""

    trial: Trial
    segments: dict                       # segment -> markers
    edges: set                           # frozenset({parent, child})
    types: dict                          # frozenset edge -> type
    loose: list = field(default_factory=list)

    def owner(self) -> dict:
        return {m: s for s, ms in self.segments.items() for m in ms}

    def named_edges(self, doc: dict) -> dict:
        """The result's joints as truth-named edges -> type (each result segment named by its markers' owner)."""
        owner = self.owner()
        name = {g: owner.get(ms[0]) for g, ms in doc["segments"].items()}
        return {frozenset((name[j["parent"]], name[j["child"]])): j["type"] for j in doc["joints"]}


def make_case(seed: int, n_segments: int, counts=None, types=None, noise_mm=0.0, occlusion=0.0, wobble_mm=0.0,
              loose=0, n_frames=300, parents=None) -> Case:
    """A random tree s0..s{n-1} (s0 the root; `parents` or drawn from `seed`), `counts` markers per segment
    (default 3 or 4), joint `types` (default drawn), simulated with all three axes of every ball joint exercised;
    each marker then wobbles on a slow sinusoid of amplitude `wobble_mm`, and `loose` random-walk markers are
    added."""
    rng = np.random.default_rng(seed)
    parents = parents if parents is not None else [int(rng.integers(0, i)) for i in range(1, n_segments)]
    types = types or [str(rng.choice(["spherical", "revolute"])) for _ in parents]
    counts = counts or [int(rng.integers(3, 5)) for _ in range(n_segments)]
    segs = {f"s{i}": {"markers": [f"m{i}_{k}" for k in range(counts[i])]} for i in range(n_segments)}
    joints = {f"j{i}": {"type": types[i - 1], "parent": f"s{p}", "child": f"s{i}"} for i, p in enumerate(parents, 1)}
    model = Model.from_dict({"units": "mm", "segments": segs, "joints": joints})
    sim = simulate(model, n_frames=n_frames, seed=seed, noise_mm=noise_mm, occlusion=occlusion, n_axes=3)
    X = sim.trial.as_array()
    labels = list(sim.trial.labels)
    t = np.arange(n_frames) / 100.0
    if wobble_mm:
        for k in range(X.shape[1]):
            d = rng.normal(size=3)
            X[:, k] += wobble_mm * np.sin(2 * np.pi * rng.uniform(0.3, 1.5) * t + rng.uniform(0, 6.3))[:, None] \
                * (d / np.linalg.norm(d))
    for k in range(loose):
        walk = np.cumsum(rng.normal(0, 3, size=(n_frames, 3)), axis=0) + rng.normal(0, 300, 3) + [0, 0, 900]
        X = np.concatenate([X, walk[:, None]], axis=1)
        labels.append(f"loose{k}")
    edges = {frozenset((f"s{p}", f"s{i}")) for i, p in enumerate(parents, 1)}
    return Case(Trial(X, labels, 100.0, f"case(seed={seed})"), {s: v["markers"] for s, v in segs.items()}, edges,
                {frozenset((f"s{p}", f"s{i}")): types[i - 1] for i, p in enumerate(parents, 1)},
                [f"loose{k}" for k in range(loose)])


@st.composite
def cases(draw, max_segments=5, noise=(0.0, 0.5), occlusion=(0.0, 0.2), wobble=(0.0, 1.0), loose=(0, 1)):
    """A :class:`Case` with 2..`max_segments` segments of 3-4 markers, noise and wobble (mm) and occlusion drawn
    from the given choices, and 0 or 1 loose marker."""
    return make_case(draw(st.integers(0, 2**16)), draw(st.integers(2, max_segments)),
                     noise_mm=draw(st.sampled_from(noise)), occlusion=draw(st.sampled_from(occlusion)),
                     wobble_mm=draw(st.sampled_from(wobble)), loose=draw(st.sampled_from(loose)))
