"""What ``identcheck derive`` returns: every derivation, checked against the printed paper and written out."""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class DeriveResult:
    """Every derivation, its checks against the print, and the files written.

    Attributes
    ----------
    derivations : tuple of Derivation
        In canonical order (see :func:`identcheck.derive.derive_all`).
    out : str
        The directory the rendered Markdown went to.
    files : tuple of str
        The files written there.
    generated : tuple
        The solvers' generated modules compared with a fresh print of these derivations, one status per
        module (:class:`identcheck.solve.generated.writer.ModuleStatus`: ``ok`` when it holds the print).
    seed : dict
        The derivations' cache as the package ships it (:func:`identcheck.certify.seed.status`): ``applies``
        (the running SymPy and Python are the ones it was made with), ``current`` (it holds every file the
        sources' keys name), ``missing``, ``made_with``, and ``written`` when this run rewrote it.
    """

    derivations: tuple
    out: str
    files: tuple
    generated: tuple = ()
    seed: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Every check agrees with the print or is a recorded erratum, every generated module is current, and the
        shipped cache serves the sources (where it applies: under other versions the cache derives anew)."""
        seed_ok = not self.seed.get("applies") or self.seed.get("current", False)
        return all(dv.ok for dv in self.derivations) and all(g.ok for g in self.generated) and seed_ok

    def to_dict(self) -> dict:
        """``{"ok", "out", "files", "derivations": [{name, title, source, ok, checks}], "generated": [{case,
        path, up_to_date, written, ok}], "seed": {...}}``, as ``identcheck derive --json`` prints it."""
        return {
            "ok": self.ok,
            "out": self.out,
            "files": list(self.files),
            "derivations": [{
                "name": dv.name, "title": dv.title, "source": dv.source, "ok": dv.ok,
                "checks": [{"name": c.name, "where": c.where, "agrees": bool(c.agrees), "erratum": c.erratum,
                            "ok": c.ok, "note": c.note or (c.derived if isinstance(c.derived, str) else "")}
                           for c in dv.checks],
            } for dv in self.derivations],
            "generated": [g.to_dict() for g in self.generated],
            "seed": dict(self.seed),
        }


def derive_and_write(out_dir) -> DeriveResult:
    """Run every derivation (cached), check it against the print and write it as Markdown to ``out_dir``."""
    from identcheck.derive import derive_all
    from identcheck.derive import render

    dvs = derive_all()
    paths = render.write(dvs, out_dir)
    return DeriveResult(derivations=tuple(dvs), out=str(out_dir), files=tuple(str(p) for p in paths))
