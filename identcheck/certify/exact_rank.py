"""Exact generic rank of the sampled M-matrix over the rationals, as a replayable certificate.

Sample points are drawn *on the output set* with rational coordinates: rational constant
parameters, and rational cos/sin of every angle through the tangent half-angle
t ↦ ((1 − t²)/(1 + t²), 2t/(1 + t²)). M is then a matrix of rationals and its rank is computed
exactly (no floats). A non-zero maximal minor at one such point proves that the minor, a
polynomial on the output set, is not identically zero: the generic rank is at least that rank,
deterministically. A rank below the number of unknowns at random points is only a lower
bound and is reported with ``deterministic: false``.
"""
from __future__ import annotations

import json
import random
from dataclasses import asdict, dataclass, field
from fractions import Fraction

import numpy as np
import sympy as sp

from identcheck import derive
from identcheck.certify.seal import seal
from identcheck.errors import InputError
from identcheck.exact.algebra import half_angle as exact_half_angle
from identcheck.exact.linalg import maximal_minor
from identcheck.progress import Progress
from identcheck.symbols import Case, case as get_case

FORMAT = "identcheck.rank-certificate/1"


def rational_text(v) -> str:
    """Exact text of a rational (as certificates store it)."""
    return str(sp.Rational(v))


def _rat(text) -> sp.Rational:
    """The rational a certificate stores as text; a zero denominator is a malformed value (ValueError, which
    :func:`verify` reports), not a division."""
    try:
        return sp.Rational(str(text))
    except ZeroDivisionError:
        raise ValueError(f"{text!r} has a zero denominator") from None


def _shape_problems(cert: dict) -> list:
    """The fields a rank certificate is rebuilt from, checked for their JSON kind before anything is read from
    them: each one missing or of another kind, named (a rebuilt certificate then judges the values)."""
    def number_text(v) -> bool:
        return isinstance(v, str) or (isinstance(v, (int, float)) and not isinstance(v, bool))

    def point(v) -> bool:
        return isinstance(v, list) and len(v) > 0 and all(number_text(c) for c in v)

    kinds = {"joint": (lambda v: isinstance(v, str), "a joint type (text)"),
             "p": (lambda v: type(v) is int, "an integer"), "q": (lambda v: type(v) is int, "an integer"),
             "seed": (lambda v: type(v) is int, "an integer"),
             "parameters": (lambda v: isinstance(v, dict) and all(number_text(x) for x in v.values()),
                            "an object of parameter name to rational (text)"),
             "samples": (lambda v: isinstance(v, list) and all(
                 isinstance(x, dict) and isinstance(x.get("t"), list) and all(number_text(t) for t in x["t"])
                 and point(x.get("xyz")) for x in v), 'a list of {"t": [angles], "xyz": [coordinates]}')}
    problems = []
    for key, (ok, what) in kinds.items():
        if key not in cert:
            problems.append(f"malformed certificate: field {key!r} missing")
        elif not ok(cert[key]):
            problems.append(f"malformed certificate: field {key!r} is {str(json.dumps(cert[key]))[:60]}, not {what}")
    return problems


def half_angle(t) -> tuple:
    """Exact (cos, sin) of the angle whose tangent of half is the rational ``t``."""
    return exact_half_angle(sp.Rational(t))


def _draw(rng: random.Random, lo: int, hi: int, den: int = 16) -> sp.Rational:
    return sp.Rational(rng.randint(lo * den, hi * den), rng.randint(1, den))


def draw_parameters(cs: Case, rng: random.Random) -> dict:
    """Random rational constants (lengths in arbitrary units) and half-angle tangents."""
    params = {}
    for s in cs.constants:
        lo = 1 if s.is_positive else -3
        v = _draw(rng, lo, 3)
        while v == 0:
            v = _draw(rng, lo, 3)
        params[str(s)] = v
    for a in cs.constant_angles:
        params["t_" + a.name] = sp.Rational(rng.randint(1, 15), rng.randint(16, 31))  # α ∈ (0, π/2)
    return params


TANGENT_NUMERATORS, TANGENT_DENOMINATORS = (-40, 40), (1, 13)


def distinct_tangents() -> int:
    """How many distinct half-angle tangents :func:`draw_angles` can draw: the most samples a case can have
    (675)."""
    (a0, a1), (b0, b1) = TANGENT_NUMERATORS, TANGENT_DENOMINATORS
    return len({Fraction(a, b) for a in range(a0, a1 + 1) for b in range(b0, b1 + 1)})


def draw_angles(cs: Case, rng: random.Random, n: int) -> list:
    """n samples of per-sample half-angle tangents, distinct in *every* variable.

    Distinct tuples are not enough: a row of M may depend on some variables only (for
    revolute (2,1) on β alone, since θ turns the sample about the z axis and M sees only
    R² and z), so a repeated value of one variable can repeat a row. The tangents come from a finite
    set (:func:`distinct_tangents`), so n is at most its size: more would never finish.
    """
    if n > distinct_tangents():
        raise InputError(f"--samples {n}: at most {distinct_tangents()} (the samples' half-angle tangents are "
                         f"distinct, drawn from that many rationals)")
    columns = []
    for _ in cs.variables:
        seen = []
        while len(seen) < n:
            t = sp.Rational(rng.randint(*TANGENT_NUMERATORS), rng.randint(*TANGENT_DENOMINATORS))
            if t not in seen:
                seen.append(t)
        columns.append(seen)
    return [tuple(col[i] for col in columns) for i in range(n)]


def _substitution(cs: Case, params: dict, ts) -> dict:
    sub = {s: _rat(params[str(s)]) for s in cs.constants}
    for a in cs.constant_angles:
        sub[a.cos], sub[a.sin] = half_angle(params["t_" + a.name])
    for a, t in zip(cs.variables, ts):
        sub[a.cos], sub[a.sin] = half_angle(t)
    return sub


def _derivation(cs: Case):
    """The case's derivation for computing: its expressions' values (kept on disk between processes by
    :mod:`identcheck.derive.cache`, keyed by the derivation's sources, so the table does not run SymPy's
    derivation on every call). What a certificate prints of it comes from :func:`_printed`."""
    return derive.for_case(cs)


def _printed(cs: Case) -> dict:
    """The printed forms a certificate records — the unknowns' expressions and, when the raw expansion had
    dependent columns, its monomials and relations — from a fresh derivation (a pickle round trip can change
    how an expression prints), kept on disk beside the derivation."""
    def render(dv) -> dict:
        exp = dv.results.get("expansion")
        return {"Y": [str(e) for e in dv.result("Y")],
                "expansion": None if not exp else {
                    "unknowns": [str(u) for u in exp["unknowns"]],
                    "relations": [[str(c) for c in rel] for rel in exp["relations"]],
                    "meaning": exp["meaning"]}}
    return derive.printed_forms(derive.CASE_DERIVATION[cs.key], render)


def sample_point(cs: Case, params: dict, ts) -> tuple:
    """The exact rational output (x, y, z) for constants ``params`` and sample angles ``ts``."""
    forward = _derivation(cs).result("forward")
    sub = _substitution(cs, params, ts)
    return tuple(sp.Rational(e.xreplace(sub)) for e in forward)


def m_rows(cs: Case, points, progress=None) -> tuple:
    """The exact rational matrix M and vector K built from sample points."""
    dv = _derivation(cs)
    M, K, inv = dv.result("M"), dv.result("K"), dv.result("invariants")
    rows, rhs = [], []
    line = Progress(progress, first_after_s=1.0)
    for k, pt in enumerate(points):
        line(lambda: f"rows of M: {k} of {len(points)} ({line.elapsed:.0f} s)")
        sub = dict(zip(cs.sample, pt))
        sub_inv = {k: v.xreplace(sub) for k, v in inv.items()}
        rows.append([sp.Rational(m.xreplace(sub_inv).xreplace(sub)) for m in M])
        rhs.append(sp.Rational(K.xreplace(sub_inv).xreplace(sub)))
    return rows, rhs


def exact_rank(rows) -> tuple:
    """Rank over QQ with the pivot rows and columns of a non-zero maximal minor and its value
    (:func:`identcheck.exact.linalg.maximal_minor`; the minor as a SymPy Rational)."""
    rank, row_piv, col_piv, det = maximal_minor(rows)
    return rank, row_piv, col_piv, sp.Rational(det.numerator, det.denominator)


@dataclass(frozen=True)
class RankCertificate:
    """Everything needed to replay an exact rank computation (see :func:`verify`): the result of
    ``identcheck rank``.

    Rationals are stored as exact text (``"-3/7"``); ``to_dict()`` is the saved certificate and the
    contract's ``rank`` JSON (``joint``, ``p``, ``q``, ``unknowns``, ``rank``, ``full_rank``, ``exact``).
    """

    joint: str
    p: int
    q: int
    unknowns: list
    unknown_exprs: list
    rank: int
    full_rank: bool
    exact: bool
    deterministic: bool
    seed: int
    n_samples: int
    parameters: dict
    samples: list
    pivot_rows: list
    pivot_columns: list
    minor_determinant: str
    numeric_rank: int
    statement: str
    format: str = FORMAT
    matrix: list = field(default_factory=list)
    min_samples: int | None = None
    expansion: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The certificate's body as a JSON document (format ``/1``: what a table embeds)."""
        return asdict(self)

    def sealed(self) -> dict:
        """The standalone certificate: the body under format ``/2`` with its content hash
        (:func:`identcheck.certify.seal.seal`); what ``identcheck rank --json`` prints and ``--save`` writes."""
        return seal(self.to_dict())


def rank(joint: str, p: int, q: int, n_samples: int | None = None, seed: int = 0, progress=None) -> RankCertificate:
    """Exact rank of M built from ``n_samples`` random rational samples of the output set.

    Parameters
    ----------
    joint, p, q : the case (e.g. ``"revolute", 2, 1``).
    n_samples : int, optional
        Number of samples (rows); defaults to the number of unknowns.
    seed : int
        Seed of the rational draws; the certificate records the points themselves too.
    progress : callable, optional
        Called with a line of text at most once a second while samples and rows are computed.
    """
    cs = get_case(joint, p, q)
    if progress:
        progress(f"{joint} ({p},{q}): the derivation of M, then exact samples and the exact rank")
    n_unknowns = len(_printed(cs)["Y"])
    n = n_unknowns if n_samples is None else int(n_samples)
    if n < 1:
        raise InputError(f"--samples must be at least 1, got {n}")
    rng = random.Random(seed)
    params = draw_parameters(cs, rng)
    angles = draw_angles(cs, rng, n)
    return certificate(cs, params, angles, seed, progress)


def certificate(cs: Case, params: dict, angles: list, seed: int, progress=None) -> RankCertificate:
    """The rank certificate of case `cs` at constants `params` and per-sample half-angle tangents `angles`:
    every stored field follows from these (and `seed`, which records where they were drawn), so that
    :func:`verify` rebuilds the whole document from them and compares it field by field."""
    shown = _printed(cs)
    n_unknowns = len(shown["Y"])
    n = len(angles)
    line = Progress(progress, first_after_s=1.0)
    points = []
    for k, ts in enumerate(angles):
        line(lambda: f"sample points: {k} of {n} ({line.elapsed:.0f} s)")
        points.append(sample_point(cs, params, ts))
    rows, rhs = m_rows(cs, points, progress)
    rk, prow, pcol, det = exact_rank(rows)
    num = np.array([[float(v) for v in row] for row in rows])
    scale = np.abs(num).max(axis=0)
    numeric_rank = int(np.linalg.matrix_rank(num / np.where(scale == 0, 1, scale)))
    full = rk == n_unknowns
    statement = (
        f"The {rk}x{rk} minor of M on rows {prow} and columns {pcol} equals {det} != 0 at exact "
        f"rational points of the output set; the minor is a polynomial on the output set, so it "
        f"is non-zero for generic samples and the generic rank is at least {rk}"
        + (f" = the number of unknowns: M is generically invertible ({rk}-identifiable linear system)."
           if full else f" (a lower bound only: {n_unknowns} unknowns).")
    )
    names = [f"Y{i}" for i in range(1, n_unknowns + 1)]
    return RankCertificate(
        min_samples=n_unknowns if full else None, expansion=_expansion(shown["expansion"], rk if full else None),
        joint=cs.joint, p=cs.p, q=cs.q, unknowns=names,
        unknown_exprs=list(shown["Y"]), rank=rk, full_rank=full, exact=True,
        deterministic=full, seed=seed, n_samples=n,
        parameters={k: rational_text(v) for k, v in params.items()},
        samples=[{"t": [rational_text(t) for t in ts], "xyz": [rational_text(c) for c in pt]} for ts, pt in zip(angles, points)],
        pivot_rows=prow, pivot_columns=pcol, minor_determinant=str(det), numeric_rank=numeric_rank,
        statement=statement, matrix=[[rational_text(v) for v in row] for row in rows],
    )


def _expansion(exp: dict | None, rank_reduced) -> dict:
    """When the derivation's raw expansion had dependent columns, how the unknowns were reduced.

    The rank of the raw columns on the output set is at most (#columns − #relations), the
    relations being proved identities, and at least the certified rank of the reduced system,
    whose columns are a subset: when the two bounds meet, the rank is exact.
    """
    if not exp:
        return {}
    upper = len(exp["unknowns"]) - len(exp["relations"])
    return {
        "unknowns": list(exp["unknowns"]),
        "relations": [list(rel) for rel in exp["relations"]],
        "relation_meaning": exp["meaning"],
        "rank_upper_bound": upper,
        "rank": upper if rank_reduced == upper else None,
        "statement": (f"{len(exp['unknowns'])} unknown monomials; {len(exp['relations'])} proved linear "
                      f"relation(s) among their columns on the output set give rank <= {upper}; the reduced "
                      f"system's certified rank {rank_reduced} gives rank >= {rank_reduced}"
                      + (": the rank is exactly " + str(upper) if rank_reduced == upper else "")),
    }


@dataclass
class Verification:
    ok: bool
    problems: list


def verify(cert: dict) -> Verification:
    """Re-check a saved certificate from scratch, trusting none of its derived numbers.

    Checks that every sample point is exactly the output of the stated parameters and angles,
    rebuilds M from the points with the derivation, recomputes the exact rank and the minor; then rebuilds
    the whole certificate from its parameters and angles (:func:`certificate`) and rejects every stored
    field that differs from the rebuilt one (the matrix, the statement, the counts, the expressions of the
    unknowns, the flags, each with its JSON type), and a seed that does not draw the stored parameters and
    angles.
    """
    problems = []
    if cert.get("format") != FORMAT:
        return Verification(False, [f"unknown certificate format {cert.get('format')!r}; expected {FORMAT}"])
    shape = _shape_problems(cert)
    if shape:
        return Verification(False, shape)
    try:
        cs = get_case(cert["joint"], cert["p"], cert["q"])
        if sorted(cert["parameters"]) != sorted(draw_parameters(cs, random.Random(0))):
            return Verification(False, [f"parameters: expected exactly {', '.join(sorted(draw_parameters(cs, random.Random(0))))}"
                                        f" for {cs.joint} ({cs.p},{cs.q})"])
        params = {k: _rat(v) for k, v in cert["parameters"].items()}
        points, angles = [], []
        for i, smp in enumerate(cert["samples"]):
            ts = [_rat(t) for t in smp["t"]]
            if len(ts) != len(cs.variables):
                problems.append(f"sample {i}: {len(ts)} angles, the case has {len(cs.variables)}")
            pt = tuple(_rat(c) for c in smp["xyz"])
            if sample_point(cs, params, ts) != pt:
                problems.append(f"sample {i}: the point is not the output of the stated parameters and angles")
            points.append(pt)
            angles.append(tuple(ts))
        rows, _ = m_rows(cs, points)
        rk, prow, pcol, det = exact_rank(rows)
        seed = cert["seed"]
        if type(seed) is not int:
            raise TypeError(f"seed must be an integer, got {seed!r}")
        rebuilt = certificate(cs, params, angles, seed).to_dict() if not problems else {}
        rng = random.Random(seed)
        if not problems and (draw_parameters(cs, rng) != params or draw_angles(cs, rng, len(angles)) != angles):
            problems.append(f"seed {seed} does not draw the stored parameters and angles")
    except KeyError as exc:
        return Verification(False, [f"malformed certificate: field {exc.args[0]!r} missing"])
    except (TypeError, ValueError) as exc:          # a value of the right kind that is no rational, or no case
        return Verification(False, [f"malformed certificate: {exc}"])
    if rk != cert["rank"] or type(cert["rank"]) is not int:
        problems.append(f"rank recomputed as {rk}, certificate says {cert['rank']!r}")
    if str(det) != cert["minor_determinant"] or pcol != cert["pivot_columns"] or prow != cert["pivot_rows"]:
        problems.append(f"minor recomputed as {det} on rows {prow}, columns {pcol}; certificate differs")
    if bool(cert["full_rank"]) != (rk == len(cert["unknowns"])):
        problems.append("full_rank flag does not match the recomputed rank")
    said = {"rank", "minor_determinant", "pivot_rows", "pivot_columns"}   # reported above when they differ
    for key in sorted(set(rebuilt) | set(cert)):
        if key in said or not rebuilt:
            continue
        if key not in rebuilt:
            problems.append(f"field {key!r}: not a field of {FORMAT}")
        elif json.dumps(rebuilt[key], sort_keys=True) != json.dumps(cert.get(key), sort_keys=True):
            problems.append(f"field {key!r} differs from the one rebuilt from the certificate's parameters and samples"
                            + ("" if key in cert else " (missing)"))
    return Verification(not problems, problems)
