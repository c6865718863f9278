"""Result objects → JSON-ready dictionaries with the keys of CONTRACT.md."""
from __future__ import annotations

import numpy as np

from identcheck.io.jsonable import plain  # noqa: F401  (re-exported: results -> JSON)


def derive_report(derivations, out_dir, paths) -> dict:
    return {
        "ok": all(dv.ok for dv in derivations),
        "out": str(out_dir),
        "files": [str(p) for p in paths],
        "derivations": [{
            "name": dv.name, "title": dv.title, "source": dv.source, "ok": dv.ok,
            "checks": [{"name": c.name, "where": c.where, "agrees": bool(c.agrees), "erratum": c.erratum,
                        "ok": c.ok, "note": c.note or (c.derived if isinstance(c.derived, str) else "")}
                       for c in dv.checks],
        } for dv in derivations],
    }


def rank_report(cert) -> dict:
    return cert.to_dict()


def identify_report(results) -> dict:
    joints = {}
    for r in results:
        best = min(r.candidates, key=lambda c: c["residual_mm"])
        joints[r.joint] = {
            "type": r.type, "case": r.case, "unique": r.unique,
            "candidates": len(r.candidates), "parameter_sets": r.n_parameter_sets,
            "marker_distances": best["marker_distances"],
            "alternatives": [dict(c) for c in r.candidates if c is not best],
            "rms_residual": best["residual_mm"], "n_samples": r.n_samples,
            "parent_marker_spread_mm": r.parent_spread_mm, "markers": r.markers,
        }
    return {"joints": joints}
