"""The identifiability table: every joint type × markers (p on the parent, q on the child), p, q ∈ 0..3.

Revolute and spherical rows are settled with certificates of four kinds:

* ``exact_rank`` / ``exact_uniqueness`` — a linear system with an exact non-zero minor at a rational
  point of the output set whose solution gives the joint linearly: identifiable (one candidate);
* ``enumerated_candidates`` — every joint the data admit, verified at 50 digits, complete by a proof
  (revolute (2,1): four joints, ERRATA E1/E2; revolute (2,2): one);
* ``counterexample`` — a constructed alternative joint reproducing every sample, verified at 50 digits
  (:mod:`identcheck.certify.counterexamples`): not locally identifiable;
* ``remark1`` — Pham et al.'s Remark 1: (p, q) behaves as (q, p); more markers keep identifiability,
  fewer keep non-identifiability. The row names the case it follows from (whose row holds the proof).

Every row also carries the verdict of the Jacobian engine (:mod:`identcheck.certify.jacobian`), which needs no
hand elimination; the table checks that the two agree on ``local``. The engine alone settles the
``universal`` and ``prismatic`` rows, marked ``verdict_kind: "local"``: locality is certified, global
uniqueness is not decided (``identifiable`` false with ``identifiable_decided`` false, ``candidates`` null).
"""
from __future__ import annotations

import json

from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache

from identcheck.certify import candidates
from identcheck.certify import exact_rank as certify
from identcheck.certify import counterexamples
from identcheck.certify import jacobian
from identcheck.certify.joint_models import JOINTS, MARKERS
from identcheck.certify.seal import digest
from identcheck.io.jsonable import frozen, plain

CERTIFIED = ("revolute", "spherical")
FORMAT = "identcheck.table/1"


def _key(joint: str, p: int, q: int) -> str:
    return f"{joint}({p},{q})"


def _local_summary(c: jacobian.LocalCertificate) -> dict:
    return {"local": c.local, "min_samples": c.min_samples, "deterministic": c.deterministic,
            "probability_bound": c.probability_bound, "rank": c.full_jacobian["rank"],
            "columns": c.full_jacobian["columns"], "n_samples": c.n_samples, "statement": c.statement}


def _row(joint, p, q, identifiable, local, n_cand, min_samples, certificate) -> dict:
    return {"joint": joint, "p": p, "q": q, "identifiable": identifiable, "local": local, "candidates": n_cand,
            "min_samples": min_samples, "certificate": certificate}


def _not_local(joint, p, q, seed) -> dict:
    if p == 0 and q == 0:
        return _row(joint, p, q, False, False, None, None, {
            "kind": "vacuous", "statement": "No marker on either link: no quantity relates the joint to any marker, "
                                            "so there is nothing to identify."})
    cx = counterexamples.witness(joint, p, q, seed=seed, n_samples=8)
    chk = cx.check()
    return _row(joint, p, q, False, False, None, None, {
        "kind": "counterexample", "construction": cx.construction,
        "statement": (f"A second joint with marker distances differing by up to "
                      f"{float(chk.change):.4g} reproduces all {len(cx.data)} samples of a random {cx.key} "
                      "joint, poses given explicitly and verified at 50 digits; the construction works for an "
                      "interval of delta, so the joint is not even locally identifiable."),
        "counterexample": cx.to_dict(check=chk)})


def _base(joint: str, p: int, q: int, seed: int):
    """The row of a case settled by its own certificate, or None."""
    if p == 0 or q == 0 or (p, q) == (1, 1) or (joint, p, q) == ("spherical", 2, 1):
        return _not_local(joint, p, q, seed)
    if joint == "spherical" and (p, q) in ((3, 1), (2, 2)):
        rc = certify.rank(joint, p, q, seed=seed)
        return _row(joint, p, q, rc.full_rank, rc.full_rank, 1 if rc.full_rank else None, rc.min_samples, {
            "kind": "exact_rank", "statement": rc.statement + " The joint follows linearly from the solved unknowns "
            "(derivation back-substitution), so it is unique.", "rank_certificate": rc.to_dict()})
    if joint == "revolute" and (p, q) == (2, 1):
        rc = certify.rank(joint, p, q, seed=seed)
        en = candidates.revolute21()
        return _row(joint, p, q, en["count"] == 1, rc.full_rank, en["count"], rc.min_samples, {
            "kind": "enumerated_candidates", "statement": en["statement"], "candidates": en,
            "rank_certificate": rc.to_dict()})
    if joint == "revolute" and (p, q) == (2, 2):
        en = candidates.revolute22()
        return _row(joint, p, q, en["count"] == 1, True, en["count"], candidates.SAMPLES_21 - 2, {
            "kind": "enumerated_candidates", "statement": en["statement"], "candidates": en})
    if joint == "revolute" and (p, q) == (3, 1):
        en = candidates.revolute31()
        return _row(joint, p, q, en["count"] == 1, True, en["count"], 3, {
            "kind": "exact_uniqueness", "statement": en["statement"], "uniqueness": en})
    return None


def _derived(joint: str, p: int, q: int, rows: dict, seed: int):
    """A row from Remark 1, preferring the source that needs the fewest samples."""
    options = []
    sym = rows.get((q, p))
    if sym is not None:
        options.append((sym, "symmetry", "(p, q) behaves as (q, p): exchange the links' roles"))
    for (p0, q0), src in rows.items():
        if src["identifiable"] and p0 <= p and q0 <= q and (p0, q0) != (p, q):
            options.append((src, "more markers", "extra markers keep the joint identifiable (Remark 1)"))
        if not src["local"] and p0 >= p and q0 >= q and (p0, q0) != (p, q):
            options.append((src, "fewer markers", "a joint not identifiable with more markers is not with fewer"))
    if not options:
        return None
    options.sort(key=lambda o: (not o[0]["identifiable"], o[0]["min_samples"] or 10**6, o[1] != "symmetry"))
    src, rule, why = options[0]
    cert = {"kind": "remark1", "rule": rule, "follows_from": _key(joint, src["p"], src["q"]),
            "statement": f"Follows from {_key(joint, src['p'], src['q'])} by Remark 1 ({rule}): {why}; "
                         "that row carries the proof."}
    if not src["local"]:   # and a witness of its own, built through the same rule
        cert["counterexample"] = counterexamples.witness(joint, p, q, seed=seed, n_samples=8).to_dict()
    return _row(joint, p, q, src["identifiable"], src["local"], src["candidates"], src["min_samples"], cert)


def _certified_rows(joint: str, seed: int) -> list:
    rows = {}
    for p in MARKERS:
        for q in MARKERS:
            r = _base(joint, p, q, seed)
            if r is not None:
                rows[(p, q)] = r
    changed = True
    while changed:
        changed = False
        for p in MARKERS:
            for q in MARKERS:
                if (p, q) not in rows:
                    r = _derived(joint, p, q, rows, seed)
                    if r is not None:
                        rows[(p, q)] = r
                        changed = True
    missing = [(p, q) for p in MARKERS for q in MARKERS if (p, q) not in rows]
    if missing:
        raise RuntimeError(f"{joint}: cases not settled: {missing}")
    return [rows[(p, q)] for p in MARKERS for q in MARKERS]


def _with_engine(row: dict, seed: int) -> dict:
    c = jacobian.verdict(row["joint"], row["p"], row["q"], seed=seed)
    row["verdict_kind"] = "certified"
    row["identifiable_decided"] = True
    row["local_min_samples"] = c.min_samples
    row["local_certificate"] = _local_summary(c)
    if c.local != row["local"]:
        raise AssertionError(f"{_key(row['joint'], row['p'], row['q'])}: the Jacobian engine says local={c.local}, "
                             f"the certificate says local={row['local']}")
    return row


def _engine_row(joint: str, p: int, q: int, seed: int) -> dict:
    c = jacobian.verdict(joint, p, q, seed=seed)
    row = _row(joint, p, q, False, c.local, None, c.min_samples, {
        "kind": "local_jacobian", "statement": c.statement, "local_certificate": c.to_dict()})
    row.update(verdict_kind="local", identifiable_decided=not c.local, local_min_samples=c.min_samples,
               local_certificate=_local_summary(c))
    return row


@lru_cache(maxsize=None)
def _joint_rows(seed: int, joint: str) -> tuple:
    """The rows of one joint type (computed once per seed)."""
    if joint in CERTIFIED:
        return tuple(_with_engine(r, seed) for r in _certified_rows(joint, seed))
    return tuple(_engine_row(joint, p, q, seed) for p in MARKERS for q in MARKERS)


@dataclass(frozen=True)
class TableResult:
    """The identifiability table (``identcheck table``): one row per joint type × markers.

    Attributes
    ----------
    cases : tuple of Mapping
        Read-only rows in table order, each with the contract's keys (``joint``, ``p``, ``q``,
        ``identifiable``, ``local``, ``candidates``, ``min_samples``, ``certificate``) and the engine's.
    seed : int
        Seed of the random rational points.
    format : str
        The saved table's format name, which ``identcheck verify`` recognises.
    """

    cases: tuple
    seed: int = 0
    format: str = FORMAT

    def row(self, joint: str, p: int, q: int) -> Mapping:
        """The row of one case; ``KeyError`` if the table does not hold it."""
        for r in self.cases:
            if (r["joint"], r["p"], r["q"]) == (joint, p, q):
                return r
        raise KeyError(_key(joint, p, q))

    def to_dict(self) -> dict:
        """The contract's ``table`` JSON, also the saved table that :func:`verify` re-checks."""
        cases = plain(self.cases)
        from identcheck import __version__

        return {"format": self.format, "seed": self.seed, "made_by": f"identcheck {__version__}",
                "sha256": content_hash(cases), "cases": cases}


def content_hash(cases) -> str:
    """SHA-256 of the rows in canonical JSON (:func:`identcheck.certify.seal.digest`): what a saved table
    certifies."""
    return digest(cases)


def table(seed: int = 0, joints=None, progress=None) -> TableResult:
    """Every case with its verdict and certificate (deterministic for a given ``seed``).

    Parameters
    ----------
    seed : int
        Seed of the random rational points.
    joints : iterable of str, optional
        Only these joint types (default: all of :data:`identcheck.certify.joint_models.JOINTS`).
    progress : callable, optional
        Called with a line of text before each joint type (a few seconds each; the work is a fixed
        set of cases, so it always ends).
    """
    joints = JOINTS if joints is None else tuple(j for j in JOINTS if j in joints)
    rows = []
    for k, j in enumerate(joints):
        if progress:
            progress(f"{j} joints ({k + 1} of {len(joints)})")
        rows += _joint_rows(int(seed), j)
    return TableResult(cases=frozen(rows), seed=seed)


def verify(doc: dict, progress=None) -> list:
    """Re-check every certificate a saved table holds; returns the problems found (empty: verified).

    Rank certificates are rebuilt from their sample points, counterexamples re-verified at 50 digits
    from their stored poses, local certificates replayed at their recorded points, enumerations and
    uniqueness proofs recomputed from their seeds and compared. Then every row is recomputed whole from
    the table's seed (the table is deterministic) and compared field by field, so that no displayed
    number or statement — a counterexample's summary, a "min N", a candidate's value, a local
    certificate's rank or bound — can be edited unnoticed; each difference names the row and the field.
    ``progress``: called with a line of text per joint type (this takes seconds).
    """
    if doc.get("format") != FORMAT:
        return [f"unknown table format {doc.get('format')!r}; expected {FORMAT}"]
    problems = _schema(doc)
    if problems:
        return problems
    if "sha256" not in doc:
        problems.append("sha256: missing (a saved table carries the digest of its rows)")
    elif doc["sha256"] != content_hash(doc["cases"]):
        problems.append("sha256: the rows are not the ones the table was saved with (edited since); every row "
                        "is re-checked below")
    seed = doc.get("seed")
    if type(seed) is not int:
        problems.append(f"seed: {seed!r} is not an integer")
    recompute = {"revolute(2,1)": candidates.revolute21, "revolute(2,2)": candidates.revolute22,
                 "revolute(3,1)": candidates.revolute31}
    for row in doc.get("cases", []):
        key = _key(row["joint"], row["p"], row["q"])
        cert = row.get("certificate", {})
        kind = cert.get("kind")
        found = []
        if "rank_certificate" in cert:
            found += certify.verify(cert["rank_certificate"]).problems
        if "counterexample" in cert:
            found += counterexamples.verify_dict(cert["counterexample"])
        if kind == "local_jacobian":
            found += jacobian.replay(cert["local_certificate"])
        for part in ("candidates", "uniqueness"):
            if part in cert:
                again = recompute[key](seed=cert[part]["seed"])
                if again["count"] != cert[part]["count"] or again["count"] != row["candidates"]:
                    found.append(f"recomputed {again['count']} candidate(s); the row says {row['candidates']}")
        if kind == "remark1":
            src = next((r for r in doc["cases"] if _key(r["joint"], r["p"], r["q"]) == cert["follows_from"]), None)
            if src is None or (src["identifiable"], src["local"]) != (row["identifiable"], row["local"]):
                found.append(f"does not match the row it follows from ({cert['follows_from']})")
        if kind not in ("exact_rank", "exact_uniqueness", "enumerated_candidates", "counterexample", "remark1",
                        "vacuous", "local_jacobian"):
            found.append(f"unknown certificate kind {kind!r}")
        else:
            found += meaning(row)
        problems += [f"{key}: {f}" for f in found]
    problems += _symmetry(doc.get("cases", []))
    problems += _coverage(doc["cases"])
    if type(seed) is int:
        problems += _recomputed(doc["cases"], seed, progress)
    return problems


def _differences(saved, fresh, path: str) -> list:
    """Field paths where ``saved`` (JSON) differs from ``fresh`` (plain), with both values."""
    if isinstance(fresh, dict) and isinstance(saved, dict):
        out = []
        for k in sorted(set(fresh) | set(saved), key=str):
            if k not in saved:
                out.append(f"{path}{k}: missing")
            elif k not in fresh:
                out.append(f"{path}{k}: not a field of the recomputed row")
            else:
                out += _differences(saved[k], fresh[k], f"{path}{k}.")
        return out
    if isinstance(fresh, list) and isinstance(saved, list) and len(fresh) == len(saved):
        return [d for i, (a, b) in enumerate(zip(saved, fresh)) for d in _differences(a, b, f"{path}{i}.")]
    a, b = json.dumps(saved, sort_keys=True), json.dumps(fresh, sort_keys=True)
    if a != b:
        at = next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))
        lo = max(0, at - 25)

        def clip(t):
            return ("..." if lo else "") + t[lo:at + 35] + ("..." if len(t) > at + 35 else "")
        return [f"{path.rstrip('.')}: {clip(a)} differs from the recomputed {clip(b)}"]
    return []


def _recomputed(cases: list, seed: int, progress=None) -> list:
    """Each saved row against the same row recomputed from ``seed``: the differing fields, named."""
    out = []
    joints = [j for j in JOINTS if any(r["joint"] == j for r in cases)]
    for k, j in enumerate(joints):
        if progress:
            progress(f"recomputing the {j} rows from seed {seed} ({k + 1} of {len(joints)})")
        fresh = {(r["joint"], r["p"], r["q"]): plain(r) for r in _joint_rows(seed, j)}
        for row in cases:
            if row["joint"] != j or (j, row["p"], row["q"]) not in fresh:
                continue
            diffs = _differences(row, fresh[(j, row["p"], row["q"])], "")
            out += [f"{_key(j, row['p'], row['q'])}: field {d}" for d in diffs[:5]]
            if len(diffs) > 5:
                out.append(f"{_key(j, row['p'], row['q'])}: and {len(diffs) - 5} more fields differ")
    unknown = sorted({r["joint"] for r in cases} - set(JOINTS))
    out += [f"joint {j!r}: not a joint type of this table" for j in unknown]
    return out


def _coverage(cases: list) -> list:
    """A table answers every marker count of each joint type it covers, once: a row listed twice, a (p, q) left
    out, or no row at all is named (the rows recomputed from the seed would not notice a row that is absent)."""
    if not cases:
        return ["cases: no row; a table answers p, q = 0..3 for each of its joint types"]
    out = []
    seen: dict = {}
    for i, row in enumerate(cases):
        seen.setdefault((row["joint"], row["p"], row["q"]), []).append(i)
    out += [f"{_key(*k)}: listed {len(rows)} times (rows {', '.join(map(str, rows))})"
            for k, rows in seen.items() if len(rows) > 1]
    for j in dict.fromkeys(r["joint"] for r in cases):
        absent = [f"({p},{q})" for p in MARKERS for q in MARKERS if (j, p, q) not in seen]
        if absent:
            out.append(f"joint {j!r}: no row for p, q = {', '.join(absent)}")
    return out


ROW_TYPES = {"joint": (str,), "p": (int,), "q": (int,), "identifiable": (bool,), "local": (bool,),
             "candidates": (int, type(None)), "certificate": (dict,)}


def _schema(doc: dict) -> list:
    """Each row has the contract's fields with their types (p, q in 0..3), named by row number and field."""
    cases = doc.get("cases")
    if not isinstance(cases, list):
        return ["cases: a table holds a list of rows"]
    out = []
    for i, row in enumerate(cases):
        if not isinstance(row, dict):
            out.append(f"row {i}: not an object")
            continue
        for field, types in ROW_TYPES.items():
            v = row.get(field, KeyError)
            if v is KeyError:
                out.append(f"row {i}: field {field!r} missing")
            elif not isinstance(v, types) or (isinstance(v, bool) and bool not in types):
                out.append(f"row {i}: {field} = {v!r} has the wrong type")
            elif field in ("p", "q") and v not in MARKERS:
                out.append(f"row {i}: {field} = {v} outside {min(MARKERS)}..{max(MARKERS)}")
    return out


def meaning(row: dict) -> list:
    """Whether a row's verdict follows from its own certificate (the arithmetic is checked elsewhere):
    a counterexample family or no marker at all ⇒ neither identifiable nor local; an exact rank or
    uniqueness proof ⇒ identifiable, local, one candidate; an enumeration of n candidates ⇒ local, with n
    candidates, identifiable exactly when n = 1; the Jacobian engine ⇒ ``local`` as it certifies, never
    identifiable (it does not decide global uniqueness); and in every row, identifiable ⇒ local ⇒ a
    candidate count (1 when identifiable, more when not), not local ⇒ no count. Returns the problems,
    each naming the field."""
    cert = row.get("certificate", {})
    kind = cert.get("kind")
    ident, local, n = row.get("identifiable"), row.get("local"), row.get("candidates")
    want = {}
    if kind in ("counterexample", "vacuous"):
        want = {"identifiable": False, "local": False, "candidates": None}
    elif kind in ("exact_rank", "exact_uniqueness"):
        want = {"identifiable": True, "local": True, "candidates": 1}
        if kind == "exact_rank" and not cert.get("rank_certificate", {}).get("full_rank", False):
            return ["certificate: an exact-rank certificate without full rank proves nothing"]
    elif kind == "enumerated_candidates":
        count = cert.get("candidates", {}).get("count")
        want = {"identifiable": count == 1, "local": True, "candidates": count}
    elif kind == "local_jacobian":
        lc = cert.get("local_certificate", {}).get("local")
        want = {"identifiable": False, "local": lc}
    out = [f"{field}: the row says {row.get(field)!r}, its {kind} certificate gives {value!r}"
           for field, value in want.items() if row.get(field) != value]
    if ident and not local:
        out.append("identifiable: true, but local: false (identifiable implies local)")
    if ident and n != 1:
        out.append(f"candidates: {n!r}, but an identifiable joint has exactly one")
    if local and not ident and n is not None and n < 2:
        out.append(f"candidates: {n!r}, but a joint that is local and not identifiable has two or more")
    if local is False and n is not None:
        out.append(f"candidates: {n!r}, but a joint that is not local has no finite count")
    return out


def _symmetry(rows: list) -> list:
    """(p, q) and (q, p) rows of a joint type must agree (a joint's relative motion is symmetric: Remark 1)."""
    by = {(r["joint"], r["p"], r["q"]): r for r in rows if {"joint", "p", "q"} <= set(r)}
    out = []
    for (j, p, q), r in sorted(by.items()):
        other = by.get((j, q, p))
        if p < q and other is not None:
            for field in ("identifiable", "local", "candidates"):
                if r.get(field) != other.get(field):
                    out.append(f"{_key(j, p, q)} and {_key(j, q, p)}: {field} differs ({r.get(field)!r} vs "
                               f"{other.get(field)!r}), but swapping the links cannot change it (Remark 1)")
    return out
