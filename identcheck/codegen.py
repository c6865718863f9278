"""The one bridge from symbols to numbers: SymPy expressions → printed, compiled numeric functions.

Every formula the solvers evaluate comes from a derivation through this module; none is typed in by
hand a second time. The steps are those of a code generator: :func:`source` prints expressions as the
text of a plain Python function (SymPy's NumPy or mpmath printer, common subexpressions eliminated);
that text is what the committed modules of :mod:`identcheck.solve.generated` are made of, so the
solvers run without SymPy. :func:`compile_source` turns such text into a function, and
:class:`NumericFunction` gives it the call convention below. :func:`numeric` does all three at once,
for what is derived at run time: it evaluates the very text the generated modules hold.

Call convention: functions take a few argument *groups* (arrays whose last axis runs over the group's
symbols, in the order given) and return an array whose last axis runs over the expressions, so one
call evaluates thousands of problems (NumPy backend) or one problem at any precision (mpmath backend).

Only :func:`source` and :func:`numeric` import SymPy; evaluating a generated function needs NumPy or
mpmath alone.
"""
from __future__ import annotations

import importlib
import inspect
import keyword
import re
from functools import lru_cache

import numpy as np

BACKENDS = ("numpy", "mpmath")


class NumericFunction:
    """A generated function ``f(*groups) -> values``; its ``__doc__`` lists the symbol order.

    NumPy backend: each group has shape ``(..., len(group))``; leading shapes broadcast; the
    result has shape ``(..., n_values)``, with floating-point warnings silenced (the solvers test
    for NaN and inf themselves). mpmath backend: each group is a sequence of numbers (mpf/mpc);
    the result is a list.

    Parameters
    ----------
    function : callable
        The plain function, taking every group's symbols in order as separate arguments and
        returning a sequence of ``n_values`` values (as :func:`source` prints it).
    groups : sequence of sequence of str
        The symbol names of each argument group.
    backend : {"numpy", "mpmath"}
    name : str
    n_values : int
        How many values the function returns.
    """

    def __init__(self, function, groups, backend="numpy", name="f", n_values=None):
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; choose one of {BACKENDS}")
        self._f = function
        self.groups = tuple(tuple(str(s) for s in g) for g in groups)
        self.backend = backend
        self.name = name
        self.n_values = n_values
        order = "; ".join("(" + ", ".join(g) + ")" for g in self.groups)
        self.__doc__ = f"{name}: groups {order} -> {n_values} values"

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


def source(exprs, groups, backend="numpy", name="f") -> str:
    """The text of a Python function ``name(*symbols)`` returning the tuple of ``exprs``.

    SymPy's printer for ``backend`` with common subexpressions eliminated (``lambdify``'s code, with
    fully qualified names: ``numpy.sqrt``, ``mpmath.mpf``), so the text needs only ``import numpy``
    or ``import mpmath`` around it. Arguments are the symbols of ``groups`` in order, by name: each
    must be a distinct Python identifier (SymPy would otherwise rename it to a random dummy, and the
    text would change from run to run).
    """
    import sympy as sp

    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose one of {BACKENDS}")
    if not name.isidentifier() or keyword.iskeyword(name):
        raise ValueError(f"function name {name!r} is not a Python identifier")
    flat = [s for g in groups for s in g]
    names = [str(s) for s in flat]
    bad = [n for n in names if not n.isidentifier() or keyword.iskeyword(n) or n in BACKENDS]
    if bad or len(set(names)) != len(names):
        raise ValueError(f"argument symbols must be distinct Python identifiers (not {BACKENDS}): {names}")
    exprs = [sp.sympify(e) for e in exprs]
    if backend == "numpy":
        from sympy.printing.numpy import NumPyPrinter as Printer
    else:
        from sympy.printing.pycode import MpmathPrinter as Printer
    printer = Printer({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False,
                       "user_functions": {}})
    f = sp.lambdify(flat, exprs, modules=[backend], printer=printer, cse=True)
    modules = set(getattr(printer, "module_imports", {}))
    if not modules <= {backend}:
        raise ValueError(f"{name}: the printed code needs modules {sorted(modules)}, not only {backend}")
    text, n = re.subn(r"\Adef _lambdifygenerated\(", f"def {name}(", inspect.getsource(f).strip() + "\n")
    # a tuple, not lambdify's list: the same values, and a compiler (numba) keeps a tuple in registers where a
    # list would be allocated on every call
    text, m = re.subn(r"^(\s*)return \[(.*)\]$", r"\1return (\2,)", text, flags=re.M)
    if n != 1 or m != 1:
        raise RuntimeError(f"unexpected lambdify output for {name}:\n{text}")
    return text


def compile_source(text: str, name: str, backend: str = "numpy"):
    """The function ``name`` defined by ``text`` (from :func:`source`), compiled with its backend module."""
    namespace = {backend: importlib.import_module(backend)}
    exec(compile(text, f"<identcheck generated {backend} {name}>", "exec"), namespace)
    return namespace[name]


@lru_cache(maxsize=None)
def _cached(exprs, groups, backend, name, version):
    text = source(exprs, groups, backend, name)
    return NumericFunction(compile_source(text, name, backend), groups, backend, name, len(exprs))


def numeric(exprs, groups, backend="numpy", name="f") -> NumericFunction:
    """Generate (once; cached by expressions, groups, backend and SymPy version) a function: :func:`source`
    printed, compiled, wrapped."""
    import sympy as sp

    exprs = tuple(sp.sympify(e) for e in (exprs if isinstance(exprs, (list, tuple)) else [exprs]))
    groups = tuple(tuple(g) for g in groups)
    return _cached(exprs, groups, backend, name, sp.__version__)
