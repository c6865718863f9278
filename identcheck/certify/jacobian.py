"""Generic local identifiability from the exact rank of the Jacobian — no hand elimination.

For a :class:`~identcheck.certify.joint_models.JointModel` and N samples, J is the Jacobian of the 3qN
output coordinates with respect to all constants and every sample's variables (an angle's
column is the tangent derivative −s ∂/∂c + c ∂/∂s, so the circle c² + s² = 1 is respected).
A quantity f of the parameters is locally identifiable at a point iff its gradient lies in the
row space of J there, i.e. is orthogonal to the null space of J — so gauge freedoms (null
directions that change no output) never matter: only gauge-invariant ``interest`` quantities are
asked about.

Exactness. J is evaluated at random rational points of the output set (rational lengths,
rational cos/sin through half-angle tangents) and every rank is exact over QQ. Because J is
block structured — sample i has rows [C_i | 0 … V_i … 0] — its rank is
Σ_i rank V_i + κ, where κ = dim W, W = Σ_i {λ C_i : λ V_i = 0} is the space of constant
gradients the samples determine; the null space of J restricted to the constants is W^⊥.
The scan over N uses this decomposition (small exact matrices); the full J at the final N is
also built and its rank recomputed with :func:`identcheck.certify.exact_rank.exact_rank`, which must
agree.

What is proved, and with what probability. A non-zero r×r minor of J at one point proves that
the generic rank is ≥ r, deterministically; when J has full column rank there, every parameter
— hence every interest quantity — is generically locally identifiable, deterministically.
Any other verdict (a rank deficiency, or a gradient found in the row space while J has a null
space) is a generic fact unless the point lies on the zero set of one specific non-zero
polynomial (a generic-rank minor of J or of J with ∇f appended). After clearing the half-angle
denominators, that polynomial has degree ≤ D in the drawn coordinates, where
D = Σ_rows Σ_v w_v deg_v(row) (w = 1 for a length, 2 for a half-angle tangent, whose cos/sin
degree doubles), and every coordinate is drawn uniformly from a set S of 2^20 rationals, so
(Schwartz–Zippel, DeMillo–Lipton) a point is bad with probability ≤ D/|S|. Ranks are combined
over k independent points (maxima), so a claim is wrong with probability ≤ (D/|S|)^k, and by a
union bound over the m claims the certificate is wrong with probability ≤ m·(D/|S|)^k, which k
is chosen to push below 1e-6.

Stabilisation. κ(N) is non-decreasing in N; if a generic new sample adds nothing, no further
sample does (its subspace lies in W for generic variables). The scan stops at the first N whose
κ and verdicts equal those at N − 1 (a claim covered by the bound above).
"""
from __future__ import annotations

import json
import random
from dataclasses import asdict, dataclass, field
from fractions import Fraction
from functools import lru_cache
from pathlib import Path

import flint
import sympy as sp
from sympy.polys.domains import QQ

from identcheck.certify.seal import seal
from identcheck.certify import exact_rank as certify
from identcheck.certify.joint_models import JOINTS, MARKERS, JointModel, model as get_model
from identcheck.exact import linalg
from identcheck.symbols import Angle

FORMAT = "identcheck.local-certificate/1"
SET_BITS = 20                 # |S| = 2^20 values per drawn coordinate
SET_SIZE = 2 ** SET_BITS
DEN = 2 ** 10                 # drawn values are k / 1024
TARGET = Fraction(1, 10**6)   # the certificate's failure probability is pushed below this
MAX_SAMPLES = 40


# -- compiled exact polynomials ------------------------------------------------------------------
class _Compiled:
    """A polynomial over QQ evaluated exactly at FLINT rationals (``flint.fmpq``; sparse terms): the same
    exact values as Python's ``Fraction`` at a small part of the cost (the table's Jacobians are evaluated
    at tens of thousands of entries)."""

    __slots__ = ("terms",)

    def __init__(self, poly: sp.Poly):
        self.terms = tuple(
            (tuple((i, e) for i, e in enumerate(mon) if e), flint.fmpq(int(c.p), int(c.q)))
            for mon, c in poly.terms() if c != 0)

    def __call__(self, vals) -> flint.fmpq:
        """The value at ``vals`` (a list of ``flint.fmpq``, one per generator)."""
        out = flint.fmpq(0)
        for mon, c in self.terms:
            term = c
            for i, e in mon:
                term *= vals[i] ** e
            out += term
        return out


def _column_derivatives(P: sp.Poly, columns, gens) -> list:
    """One derivative per column: ∂/∂s for a length, −s ∂/∂c + c ∂/∂s for an Angle."""
    out = []
    for c in columns:
        if isinstance(c, Angle):
            cp, sp_ = sp.Poly(c.cos, *gens, domain=QQ), sp.Poly(c.sin, *gens, domain=QQ)
            out.append(cp * P.diff(c.sin) - sp_ * P.diff(c.cos))
        else:
            out.append(P.diff(c))
    return out


def _degree_weight(P: sp.Poly, lengths, angles, gens) -> int:
    """Σ_v w_v deg_v(P): lengths weigh 1, angles 2 per degree in (cos, sin) jointly.

    After substituting cos, sin = (1 − t², 2t)/(1 + t²) and clearing (1 + t²)^k, a polynomial of
    joint degree k in (cos, sin) has degree ≤ 2k in t.
    """
    if P.is_zero:
        return 0
    idx = {g: i for i, g in enumerate(gens)}
    monoms = P.monoms()
    total = sum(max(mon[idx[s]] for mon in monoms) for s in lengths)
    for a in angles:
        i, j = idx[a.cos], idx[a.sin]
        total += 2 * max(mon[i] + mon[j] for mon in monoms)
    return total


@dataclass(frozen=True)
class _Symbolic:
    """The one-sample Jacobian, interest gradients and degree data of a model, compiled once."""

    gens: tuple
    n_const: int
    n_var: int
    J1: tuple          # rows (one per output) of compiled entries over const + var columns
    grads: tuple       # per interest: compiled entries over const + var (sample 0) columns
    row_degree: int    # Σ over one sample's rows of Σ_v w_v deg_v(row)
    grad_degree: int   # max over interest of Σ_v w_v deg_v(f)


@lru_cache(maxsize=1)
def _symbolic_key() -> str:
    """What the compiled Jacobians depend on: this module (the differentiation and compilation), the joint
    models and the symbols, with SymPy's version (:func:`identcheck.derive.cache.files_key`), and python-flint's,
    whose rationals they hold."""
    import hashlib

    from identcheck.derive.cache import files_key

    here = Path(__file__).resolve()
    key = files_key([here, here.parent / "joint_models.py", here.parents[1] / "symbols.py"])
    return hashlib.sha256(f"{key} flint {flint.__version__}".encode()).hexdigest()[:20]


@lru_cache(maxsize=None)
def symbolic(m: JointModel) -> _Symbolic:
    """Differentiate a model once: columns are constants then one sample's variables. Cached in memory and,
    keyed by :func:`_symbolic_key` and the case, on disk between processes (:func:`identcheck.derive.cache.
    entry`): the compiled entries are exact rational data, the same whichever process differentiated them."""
    from identcheck.derive.cache import entry

    return entry("jacobians", _symbolic_key(), m.key, lambda: _differentiate(m))


def _differentiate(m: JointModel) -> _Symbolic:
    """:func:`symbolic`'s work: SymPy differentiates each output by each column, and compiles the results."""
    c_len, c_ang = list(m.constants), list(m.constant_angles)
    v_len, v_ang = list(m.per_sample_lengths), list(m.variables)
    gens = tuple(c_len + [x for a in c_ang for x in (a.cos, a.sin)]
                 + v_len + [x for a in v_ang for x in (a.cos, a.sin)])
    lengths, angles = c_len + v_len, c_ang + v_ang
    columns = c_len + c_ang + v_len + v_ang      # constants, then one sample's variables
    poly = lambda e: sp.Poly(e, *gens, domain=QQ)
    outs = [poly(o) for o in m.outputs]
    J1 = tuple(tuple(_Compiled(e) for e in _column_derivatives(P, columns, gens)) for P in outs)
    grads, gdeg = [], 0
    for f in m.interest:
        if f.angle is not None:
            row = [poly(int(c == f.angle)) for c in columns]
        else:
            F = poly(f.expr)
            row = _column_derivatives(F, columns, gens)
            gdeg = max(gdeg, _degree_weight(F, lengths, angles, gens))
        grads.append(tuple(_Compiled(e) for e in row))
    rdeg = sum(_degree_weight(P, lengths, angles, gens) for P in outs)
    return _Symbolic(gens=gens, n_const=len(c_len) + len(c_ang), n_var=len(v_len) + len(v_ang),
                     J1=J1, grads=tuple(grads), row_degree=rdeg, grad_degree=gdeg)


# -- random rational points --------------------------------------------------------------------
def _draw_length(rng: random.Random, positive: bool) -> Fraction:
    if positive:
        return Fraction(rng.randrange(1, SET_SIZE + 1), DEN)
    return Fraction(rng.randrange(-SET_SIZE // 2, SET_SIZE // 2), DEN)


def _draw_t(rng: random.Random) -> Fraction:
    return Fraction(rng.randrange(-SET_SIZE // 2, SET_SIZE // 2), DEN)


def _half(t: Fraction) -> tuple:
    return (1 - t * t) / (1 + t * t), 2 * t / (1 + t * t)


class _Point:
    """One random point: constants, and samples drawn lazily (each from its own seeded stream)."""

    def __init__(self, m: JointModel, seed: int, index: int):
        self.m, self.seed, self.index = m, seed, index
        rng = random.Random(f"identcheck.jacobian:{seed}:{index}:constants")
        self.lengths = {str(s): _draw_length(rng, bool(s.is_positive)) for s in m.constants}
        self.angles = {a.name: _draw_t(rng) for a in m.constant_angles}
        self.samples = []
        base = [self.lengths[str(s)] for s in m.constants]
        for a in m.constant_angles:
            base += list(_half(self.angles[a.name]))
        self._base = base

    @classmethod
    def from_record(cls, m: JointModel, rec: dict) -> "_Point":
        """The point a certificate recorded (its samples only; no draws)."""
        pt = cls.__new__(cls)
        pt.m, pt.seed, pt.index = m, None, None
        pt.lengths = {str(s): Fraction(rec["constants"][str(s)]) for s in m.constants}
        pt.angles = {a.name: Fraction(rec["constant_angles_t"][a.name]) for a in m.constant_angles}
        pt.samples = [({str(s): Fraction(smp[str(s)]) for s in m.per_sample_lengths},
                       {a.name: Fraction(smp["t_" + a.name]) for a in m.variables}) for smp in rec["samples"]]
        base = [pt.lengths[str(s)] for s in m.constants]
        for a in m.constant_angles:
            base += list(_half(pt.angles[a.name]))
        pt._base = base
        return pt

    def sample_qq(self, i: int) -> list:
        """:meth:`sample` as ``flint.fmpq`` (what the compiled entries take), converted once per sample."""
        cache = self.__dict__.setdefault("_qq", {})
        if i not in cache:
            cache[i] = [linalg.qq(v) for v in self.sample(i)]
        return cache[i]

    def sample(self, i: int) -> list:
        while len(self.samples) <= i:
            if self.seed is None:
                raise IndexError(f"the recorded point has {len(self.samples)} samples; sample {i} was asked for")
            j = len(self.samples)
            rng = random.Random(f"identcheck.jacobian:{self.seed}:{self.index}:sample:{j}")
            lengths = {str(s): _draw_length(rng, bool(s.is_positive)) for s in self.m.per_sample_lengths}
            angles = {a.name: _draw_t(rng) for a in self.m.variables}
            self.samples.append((lengths, angles))
        lengths, angles = self.samples[i]
        vals = self._base + [lengths[str(s)] for s in self.m.per_sample_lengths]
        for a in self.m.variables:
            vals += list(_half(angles[a.name]))
        return vals

    def record(self) -> dict:
        return {"constants": {k: str(v) for k, v in self.lengths.items()},
                "constant_angles_t": {k: str(v) for k, v in self.angles.items()},
                "samples": [{**{k: str(v) for k, v in ls.items()},
                             **{"t_" + k: str(v) for k, v in an.items()}} for ls, an in self.samples]}


# -- exact linear algebra: identcheck.exact.linalg ------------------------------------------------
def _rowspace(rows, ncols) -> list:
    """An echelon basis (list of ``flint.fmpq`` rows) of the span of ``rows``."""
    return linalg.rowspace(rows, ncols)


def _rank(rows, ncols) -> int:
    return linalg.rank(rows, ncols)


def _left_null(rows, ncols) -> list:
    """Basis of {λ : λ·A = 0} for the matrix A given by ``rows`` (len(rows) × ncols)."""
    return linalg.left_nullspace(rows, ncols)


def _null(rows, ncols) -> list:
    """Basis of {x : A x = 0}."""
    return linalg.nullspace(rows, ncols)


def _in_span(basis, vec, ncols, basis_rank=None) -> bool:
    if not any(vec):
        return True
    if basis_rank is None:
        basis_rank = _rank(basis, ncols)
    return _rank(basis + [vec], ncols) == basis_rank


# -- the scan over N at one point --------------------------------------------------------------
class _Scan:
    """Incremental exact ranks at one point as samples are added."""

    def __init__(self, m: JointModel, sym: _Symbolic, point: _Point):
        self.m, self.sym, self.pt = m, sym, point
        self.W = []          # basis of Σ_{i ≥ 0} P_i (constant columns)
        self.Wrest = []      # basis of Σ_{i ≥ 1} P_i
        self.rank_var = 0    # Σ_i rank V_i
        self.block0 = None   # sample 0's rows [C_0 | V_0]
        self.grad_vals = None
        self.var_full_row = True   # every sample's variable block has full row rank
        self.records = []    # per N: (rank of the variable columns, κ, verdicts, var_full_row, W)

    def ensure(self, n: int) -> tuple:
        """The record at N = n samples (computed once)."""
        while len(self.records) < n:
            self.add(len(self.records))
            self.records.append((self.rank_var, self.kappa, self.identifiable(), self.var_full_row, self.W))
        return self.records[n - 1]

    def sample_block(self, i: int) -> list:
        vals = self.pt.sample_qq(i)
        return [[e(vals) for e in row] for row in self.sym.J1]

    def add(self, i: int) -> None:
        nc, nv = self.sym.n_const, self.sym.n_var
        block = self.sample_block(i)
        C = [row[:nc] for row in block]
        V = [row[nc:] for row in block]
        rv = _rank(V, nv)
        self.rank_var += rv
        self.var_full_row = self.var_full_row and rv == len(V)
        L = [[linalg.qq(x) for x in lam] for lam in _left_null(V, nv)]
        P = [[sum((lam[k] * C[k][j] for k in range(len(C))), flint.fmpq(0)) for j in range(nc)] for lam in L]
        if i == 0:
            self.block0 = block
            vals = self.pt.sample_qq(0)
            self.grad_vals = [[e(vals) for e in g] for g in self.sym.grads]
        else:
            self.Wrest = _rowspace(self.Wrest + P, nc)
        self.W = _rowspace(self.W + P, nc)

    @property
    def kappa(self) -> int:
        return len(self.W)

    def identifiable(self) -> list:
        """Per interest quantity: is its gradient in the row space of J (at this point)?"""
        nc, nv = self.sym.n_const, self.sym.n_var
        out = []
        basis = basis_rank = None
        for f, g in zip(self.m.interest, self.grad_vals):
            if f.per_sample:
                if basis is None:
                    basis = [list(r) for r in self.block0] + [list(w) + [0] * nv for w in self.Wrest]
                    basis_rank = _rank(basis, nc + nv)
                out.append(_in_span(basis, g, nc + nv, basis_rank))
            else:
                if any(g[nc:]):
                    raise ValueError(f"interest {f.name} depends on per-sample variables but is not per_sample")
                out.append(_in_span(self.W, g[:nc], nc, len(self.W)))   # W is an echelon basis
        return out


def point(m: JointModel, seed: int = 0, index: int = 0) -> _Point:
    """The ``index``-th random rational point that :func:`local_identifiability` draws for ``seed``."""
    return _Point(m, seed, index)


def full_jacobian(m: JointModel, pt: _Point, n: int, exact=Fraction) -> list:
    """The full exact Jacobian (3qN rows × (n_const + N·n_var) columns) at the point ``pt``; entries
    ``Fraction`` (or ``flint.fmpq`` with ``exact=flint.fmpq``)."""
    sym = symbolic(m)
    nc, nv = sym.n_const, sym.n_var
    convert = linalg.to_fraction if exact is Fraction else (lambda v: v)
    zero = exact(0)
    rows = []
    for i in range(n):
        vals = pt.sample_qq(i)
        for r_ in sym.J1:
            ent = [convert(e(vals)) for e in r_]
            row = ent[:nc] + [zero] * (nv * i) + ent[nc:] + [zero] * (nv * (n - 1 - i))
            rows.append(row)
    return rows


# -- the certificate -----------------------------------------------------------------------------
@dataclass
class LocalCertificate:
    """Everything needed to replay a local identifiability verdict."""

    joint: str
    p: int
    q: int
    local: bool
    min_samples: int | None
    vacuous: bool
    deterministic: bool
    n_samples: int
    stable: bool
    constants: list
    per_sample_variables: list
    outputs_per_sample: int
    interest: list
    ranks: list
    full_jacobian: dict
    null_space_constants: list
    seed: int
    n_points: int
    set_size: int
    degree_bound: int
    claims: int
    probability_bound: str
    points: list
    statement: str
    notes: list = field(default_factory=list)
    format: str = FORMAT

    def to_dict(self) -> dict:
        """The certificate's body (format ``/1``: what a table embeds)."""
        return asdict(self)

    def sealed(self) -> dict:
        """The standalone certificate: the body under format ``/2`` with its content hash
        (:func:`identcheck.certify.seal.seal`), which ``identcheck verify`` checks before replaying it."""
        return seal(self.to_dict())

    def to_json(self, **kw) -> str:
        return json.dumps(self.to_dict(), **kw)


def _vec(names, v) -> dict:
    return {n: str(x) for n, x in zip(names, v) if x != 0}


def _run(m: JointModel, sym: _Symbolic, scans: list, n_samples):
    """Combine the points' records N = 1, 2, … until stable (or up to ``n_samples``)."""
    history = []   # per N: combined ranks and verdicts
    n_max = n_samples if n_samples is not None else MAX_SAMPLES
    stable = False
    for n in range(1, n_max + 1):
        recs = [sc.ensure(n) for sc in scans]
        rank_J = [r_[0] + r_[1] for r_ in recs]
        verdicts = [r_[2] for r_ in recs]
        # combine: rank [J; ∇f] = rank J + (0 if identifiable else 1); take maxima over points
        R = max(rank_J)
        ident = [max(rj + (0 if v[i] else 1) for rj, v in zip(rank_J, verdicts)) == R
                 for i in range(len(m.interest))]
        history.append({"N": n, "rank_J": R, "rank_variables": max(r_[0] for r_ in recs),
                        "kappa": max(r_[1] for r_ in recs), "columns": sym.n_const + n * sym.n_var,
                        "rows": len(sym.J1) * n, "identifiable": ident,
                        "points_agree": len(set(rank_J)) == 1 and all(v == verdicts[0] for v in verdicts)})
        if n_samples is None and n >= 2:
            prev, cur = history[-2], history[-1]
            done_max = cur["kappa"] == sym.n_const and all(ident)
            if (cur["kappa"] == prev["kappa"] and cur["identifiable"] == prev["identifiable"]) or done_max:
                stable = True
                break
    if n_samples is not None and len(history) >= 2:
        stable = history[-1]["kappa"] == history[-2]["kappa"]
    return history, stable


def local_identifiability(m: JointModel, n_samples: int | None = None, seed: int = 0) -> LocalCertificate:
    """Decide generic local identifiability of ``m``'s interest quantities (see module docstring).

    Parameters
    ----------
    m : JointModel
        From :func:`identcheck.certify.joint_models.model`.
    n_samples : int, optional
        Evaluate at exactly this many samples (the scan still starts at 1 for min_samples);
        by default N grows until κ = rank J − rank(variable columns) and the verdicts stop changing.
    seed : int
        Seed of the rational draws (the certificate records the points themselves too).
    """
    if n_samples is not None and int(n_samples) < 1:
        raise ValueError(f"n_samples must be at least 1, got {n_samples}")
    sym = symbolic(m)
    k = 2
    scans = [_Scan(m, sym, _Point(m, seed, j)) for j in range(k)]
    while True:
        history, stable = _run(m, sym, scans, n_samples)
        if _bound(m, sym, history, k)[2] < TARGET or k >= 8:
            break
        k += 1
        scans.append(_Scan(m, sym, _Point(m, seed, k - 1)))
    return _assemble(m, sym, scans, history, stable, seed)


def _bound(m: JointModel, sym: _Symbolic, history: list, k: int) -> tuple:
    """(degree bound D, number of claims, failure probability claims·(D/|S|)^k)."""
    degree = history[-1]["N"] * sym.row_degree + sym.grad_degree
    claims = len(history) * (len(m.interest) + 1)
    return degree, claims, claims * Fraction(degree, SET_SIZE) ** k


def _assemble(m: JointModel, sym: _Symbolic, scans: list, history: list, stable: bool, seed: int) -> LocalCertificate:
    """The certificate from the scans' records (shared by computing and replaying)."""
    k = len(scans)
    n = history[-1]["N"]
    rows = len(sym.J1) * n
    degree, claims, bound = _bound(m, sym, history, k)
    last = history[-1]
    ident = last["identifiable"]
    vacuous = not m.interest
    local = bool(ident) and all(ident)
    min_samples = next((h["N"] for h in history if h["identifiable"] and all(h["identifiable"])), None) \
        if local else None
    per_min = []
    for i in range(len(m.interest)):
        first = next((h["N"] for h in history if h["identifiable"][i]), None)
        per_min.append(first if ident[i] else None)

    # the full Jacobian at point 0 and the final N, ranked by certify.exact_rank
    pt0 = scans[0].pt
    cols = sym.n_const + n * sym.n_var
    if rows and cols:
        rk, prow, pcol, det = certify.exact_rank(full_jacobian(m, pt0, n, exact=flint.fmpq))
    else:
        rk, prow, pcol, det = 0, [], [], sp.Integer(1)
    rank_var0, kappa0, _, var_full_row0, W0 = scans[0].records[n - 1]
    decomposed = rank_var0 + kappa0
    if rk != decomposed:
        raise AssertionError(f"{m.key}: full Jacobian rank {rk} != decomposed rank {decomposed}")
    full_column = rows > 0 and rk == cols
    # deterministic verdicts: full column rank proves identifiability; no rows, or variable blocks of
    # full row rank (W = 0 generically: the output set is open in R^3q), prove that no constant
    # quantity with a non-zero gradient is identifiable
    nothing_learnt = rows == 0 or (var_full_row0 and kappa0 == 0)
    const_ask = any(not f.per_sample for f in m.interest)
    deterministic = (local and full_column) or vacuous or (not local and nothing_learnt and
                                                             (const_ask or rows == 0))
    det_text = str(det)
    full = {"rows": rows, "columns": cols, "rank": rk, "full_column_rank": full_column,
            "pivot_rows": prow, "pivot_columns": pcol,
            "minor_determinant": det_text if len(det_text) <= 400 else f"{det_text[:60]}…({len(det_text)} chars)",
            "minor_nonzero": det != 0}

    names_c = m.constant_columns
    null_c = [_vec(names_c, v) for v in _null(W0, sym.n_const)] if sym.n_const else []
    interest = [{"name": f.name, "description": f.description, "per_sample": f.per_sample,
                 "identifiable": bool(ok), "min_samples": mn}
                for f, ok, mn in zip(m.interest, ident, per_min)]
    p_text = f"{float(bound):.3g}"
    points_agree = all(h["points_agree"] for h in history)
    statement = _statement(m, n, rk, rows, cols, det, full_column, local, vacuous, min_samples, stable,
                           degree, k, claims, bound, points_agree, last, deterministic, nothing_learnt)
    return LocalCertificate(
        joint=m.joint, p=m.p, q=m.q, local=local, min_samples=min_samples, vacuous=vacuous,
        deterministic=deterministic, n_samples=n, stable=stable, constants=names_c,
        per_sample_variables=m.variable_columns, outputs_per_sample=len(sym.J1), interest=interest,
        ranks=[{k_: v for k_, v in h.items() if k_ != "identifiable"} for h in history],
        full_jacobian=full, null_space_constants=null_c, seed=seed, n_points=k, set_size=SET_SIZE,
        degree_bound=degree, claims=claims, probability_bound=p_text,
        points=[sc.pt.record() for sc in scans], statement=statement, notes=list(m.notes))


def _statement(m, n, rk, rows, cols, det, full_column, local, vacuous, min_samples, stable,
               degree, k, claims, bound, agree, last, deterministic, nothing_learnt) -> str:
    parts = []
    if vacuous:
        parts.append(f"{m.key}: these markers define no joint quantity (nothing to identify); reported as "
                     "not identifiable.")
    parts.append(
        f"At N = {n} samples the exact Jacobian ({rows} x {cols}) has rank {rk} at a random rational point"
        + (f": a non-zero {rk}x{rk} minor proves generic rank >= {rk} (deterministic)." if rk else "."))
    parts.append(f"Rank of the variable columns {last['rank_variables']}, so the samples determine "
                 f"{last['kappa']} of the {len(m.constant_columns)} constant directions"
                 + (" (the rank had stopped growing)." if stable else " (N was fixed; not shown stable)."))
    if local and full_column:
        parts.append("J has full column rank: every parameter, hence every interest quantity, is generically "
                     f"locally identifiable from {n} samples — deterministic.")
    elif local:
        parts.append("Every interest quantity's gradient lies in the row space of J.")
    else:
        good = [f.name for f, ok in zip(m.interest, last["identifiable"]) if ok]
        bad = [f.name for f, ok in zip(m.interest, last["identifiable"]) if not ok]
        if bad:
            parts.append("Not locally identifiable: " + ", ".join(bad) + " (gradient not in the row space of J)"
                         + ("; identifiable: " + ", ".join(good) if good else "") + ".")
    if not local and nothing_learnt:
        parts.append("No sample carries information on the constants: " + (
            "there are no outputs." if rows == 0 else
            "each sample's variable columns have full row rank at the point, hence generically (the rank is "
            "bounded by the row count), so W = 0 and the output set is an open subset of R^3q — "
            "deterministic for every constant quantity with a non-zero gradient."))
    if min_samples is not None:
        parts.append(f"Smallest N with every interest quantity identifiable: {min_samples}.")
    if not deterministic or (local and min_samples and min_samples > 1):
        parts.append(
            ("That fewer samples do not suffice, and every verdict" if deterministic else "Every verdict")
            + f" resting on a rank deficiency or on a gradient found in the row space of a rank-deficient J is a "
            f"generic fact unless each of k = {k} independent points "
            f"is a zero of a specific non-zero polynomial of degree <= {degree} (Schwartz–Zippel, each coordinate "
            f"uniform on a set of |S| = 2^{SET_BITS} rationals); over {claims} claims the probability of any wrong "
            f"verdict is <= {claims}·({degree}/2^{SET_BITS})^{k} = {float(bound):.3g}.")
    if not agree:
        parts.append("The random points disagreed somewhere; ranks were combined by maxima.")
    return " ".join(parts)


def replay(cert: dict) -> list:
    """Re-check a saved local certificate: rebuild the model, re-evaluate the exact Jacobians at the
    recorded rational points (not the seed) and compare every rank and verdict. Returns problems."""
    if cert.get("format") != FORMAT:
        return [f"unknown certificate format {cert.get('format')!r}; expected {FORMAT}"]
    try:
        m = get_model(cert["joint"], cert["p"], cert["q"])
        sym = symbolic(m)
        scans = [_Scan(m, sym, _Point.from_record(m, rec)) for rec in cert["points"]]
        n = int(cert["n_samples"])
        history, stable = _run(m, sym, scans, None if cert["stable"] else n)
        new = _assemble(m, sym, scans, history, stable, cert["seed"]).to_dict()
    except (KeyError, TypeError, ValueError, IndexError, ZeroDivisionError) as exc:
        return [f"malformed local certificate: {exc}"]
    problems = []
    for key in ("local", "min_samples", "deterministic", "n_samples", "ranks", "full_jacobian", "interest",
                "null_space_constants", "degree_bound", "claims", "probability_bound"):
        if new[key] != cert.get(key):
            problems.append(f"{key}: recomputed {str(new[key])[:200]}, certificate says {str(cert.get(key))[:200]}")
    return problems


@lru_cache(maxsize=None)
def _cached(joint: str, p: int, q: int, n_samples, seed: int) -> LocalCertificate:
    return local_identifiability(get_model(joint, p, q), n_samples=n_samples, seed=seed)


def verdict(joint: str, p: int, q: int, n_samples: int | None = None, seed: int = 0) -> LocalCertificate:
    """Cached :func:`local_identifiability` of ``model(joint, p, q)``."""
    return _cached(str(joint).lower(), int(p), int(q), n_samples, int(seed))


def table_rows(seed: int = 0, joints=JOINTS) -> list:
    """One row per (joint, p, q), p, q ∈ 0..3: {joint, p, q, local, min_samples, certificate}."""
    rows = []
    for j in joints:
        for p in MARKERS:
            for q in MARKERS:
                c = verdict(j, p, q, seed=seed)
                rows.append({"joint": j, "p": p, "q": q, "local": c.local, "min_samples": c.min_samples,
                             "verdict_kind": "local", "certificate": c.to_dict()})
    return rows
