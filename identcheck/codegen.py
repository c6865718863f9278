"""The one bridge from symbols to numbers: SymPy expressions → generated numeric functions.

Every formula the solvers evaluate comes from a derivation through :func:`numeric`; none is
typed in by hand a second time. Functions take a few argument *groups* (arrays whose last axis
runs over the group's symbols, in the order given) and return an array whose last axis runs
over the expressions, so one call evaluates thousands of problems (NumPy backend) or one
problem at any precision (mpmath backend).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import sympy as sp

BACKENDS = ("numpy", "mpmath")


class NumericFunction:
    """A generated function ``f(*groups) -> values``; its ``__doc__`` lists the symbol order.

    NumPy backend: each group has shape ``(..., len(group))``; leading shapes broadcast; the
    result has shape ``(..., len(exprs))``. mpmath backend: each group is a sequence of
    numbers (mpf/mpc); the result is a list.
    """

    def __init__(self, exprs, groups, backend="numpy", name="f"):
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; choose one of {BACKENDS}")
        self.exprs = tuple(sp.sympify(e) for e in exprs)
        self.groups = tuple(tuple(g) for g in groups)
        self.backend = backend
        flat = [s for g in self.groups for s in g]
        modules = ["numpy"] if backend == "numpy" else ["mpmath"]
        self._f = sp.lambdify(flat, list(self.exprs), modules=modules, cse=True)
        order = "; ".join("(" + ", ".join(map(str, g)) + ")" for g in self.groups)
        self.__doc__ = f"{name}: groups {order} -> {len(self.exprs)} values"

    def __call__(self, *groups):
        if len(groups) != len(self.groups):
            raise TypeError(f"expected {len(self.groups)} argument groups, got {len(groups)}")
        if self.backend == "mpmath":
            flat = [v for g in groups for v in g]
            return list(self._f(*flat))
        flat = []
        for g, syms in zip(groups, self.groups):
            g = np.asarray(g)
            if g.shape[-1] != len(syms):
                raise ValueError(f"argument group {syms} needs last axis {len(syms)}, got shape {g.shape}")
            flat += [np.asarray(g[..., i], order="C") for i in range(len(syms))]
        with np.errstate(all="ignore"):
            out = self._f(*flat)
        return np.stack(np.broadcast_arrays(*[np.asarray(o, dtype=np.result_type(*flat, float)) for o in out]), axis=-1)


@lru_cache(maxsize=None)
def _cached(exprs, groups, backend, name, version):
    return NumericFunction(exprs, groups, backend, name)


def numeric(exprs, groups, backend="numpy", name="f") -> NumericFunction:
    """Generate (once; cached by expressions, groups, backend and SymPy version) a function."""
    exprs = tuple(sp.sympify(e) for e in (exprs if isinstance(exprs, (list, tuple)) else [exprs]))
    groups = tuple(tuple(g) for g in groups)
    return _cached(exprs, groups, backend, name, sp.__version__)
