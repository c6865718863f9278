"""What ``identcheck derive`` returns: every derivation, checked against the printed paper and written out."""
from __future__ import annotations

from dataclasses import dataclass


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
    """

    derivations: tuple
    out: str
    files: tuple
    generated: tuple = ()

    @property
    def ok(self) -> bool:
        """Every check agrees with the print or is a recorded erratum, and every generated module is current."""
        return all(dv.ok for dv in self.derivations) and all(g.ok for g in self.generated)

    def to_dict(self) -> dict:
        """``{"ok", "out", "files", "derivations": [{name, title, source, ok, checks}], "generated": [{case,
        path, up_to_date, written, ok}]}``, as ``identcheck derive --json`` prints it."""
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
        }


def derive_and_write(out_dir) -> DeriveResult:
    """Run every derivation (cached), check it against the print and write it as Markdown to ``out_dir``."""
    from identcheck.derive import derive_all
    from identcheck.derive import render

    dvs = derive_all()
    paths = render.write(dvs, out_dir)
    return DeriveResult(derivations=tuple(dvs), out=str(out_dir), files=tuple(str(p) for p in paths))
