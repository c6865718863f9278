"""Figures of a diagnosis: where the residual sits before and after, the gap per step against the noise
floor, and for each adopted effect the evidence that named it."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from identcheck.report.figure_io import figure, save, svg_text

FRAME_LABEL = "frame (as numbered in the file)"


def where_text(where: dict) -> str:
    """An effect's ``where`` as a reader writes it: ``markers RANK, RTIB; segment shank; joint knee`` (frames and
    long lists shortened), not Python's repr. A frame is given in the file's numbering when `where` has it
    (``file_frame``, as :meth:`identcheck.diagnose.workflow.Diagnosis.numbered` adds it)."""
    parts = []
    for k, v in where.items():
        if k in ("frames", "file_frames") or (k == "frame" and "file_frame" in where):
            continue
        if k == "file_frame":
            k = "frame"
        if isinstance(v, (list, tuple)):
            shown = ", ".join(str(x) for x in v[:6]) + (f" ... ({len(v)})" if len(v) > 6 else "")
        elif isinstance(v, float):
            shown = f"{v:.3g}"
        else:
            shown = str(v)
        parts.append(f"{k.replace('_', ' ')} {shown}")
    return "; ".join(parts)


def seen_alone(h) -> np.ndarray:
    """(F, M): where a marker's residual says something. A segment whose visible markers in a frame cannot
    over-determine its pose there (the root with two or fewer, a ball joint's child with one: three coordinates
    for three unknowns) fits them exactly whatever the truth: its zero residual is no evidence of a good fit, so
    the figures show those samples as missing rather than as a perfect fit."""
    chain = h.chain
    seen = h.weights > 0
    dof = {chain.root: 6} | {chain.child[j]: (3 if chain.types[j] == "spherical" else 1) for j in chain.joints}
    ok = seen.copy()
    for seg, cols in chain.seg_markers.items():
        if len(cols):
            exact = 3 * seen[:, cols].sum(axis=1) <= dof.get(seg, 6)
            ok[np.ix_(exact, cols)] = False
    return ok


def residual_map(diag, path) -> Path:
    """Residual size per marker and frame, before and after the effects, and each marker's RMS; samples that say
    nothing (occluded, or on a segment its visible markers cannot over-determine: :func:`seen_alone`) are grey."""
    ctx = diag.ctx
    maps = [np.linalg.norm(np.where(seen_alone(h)[..., None], h.residuals(), np.nan), axis=2)
            for h in (diag.before, diag.after)]
    top = np.nanpercentile(maps[0], 99.5) or 1.0
    fig = figure(figsize=(10, 8))
    axes = fig.subplots(3, 1, gridspec_kw={"height_ratios": [2, 2, 1.4]})
    for ax, m, what in zip(axes[:2], maps, ("rigid-joint model", "with the named effects")):
        ax.set_facecolor("0.8")                       # missing samples: grey, never black (a perfect fit)
        im = ax.imshow(m.T, aspect="auto", interpolation="nearest", cmap="magma", vmin=0, vmax=top,
                       extent=(diag.first_frame - 0.5, diag.first_frame + m.shape[0] - 0.5, len(ctx.labels) - 0.5, -0.5))
        ax.set_yticks(range(len(ctx.labels)), ctx.labels, fontsize=7)
        ax.set_title(f"residual |measured − model| (mm), {what}; gap {np.sqrt(np.nanmean(m ** 2)):.3g} mm", fontsize=9)
        fig.colorbar(im, ax=ax, pad=0.01)
    axes[1].set_xlabel(FRAME_LABEL)
    x = np.arange(len(ctx.labels))
    for k, (m, what) in enumerate(zip(maps, ("before", "after"))):
        axes[2].bar(x + (k - 0.5) * 0.4, np.sqrt(np.nanmean(m ** 2, axis=0)), 0.4, label=what)
    axes[2].axhline(diag.ctx.noise.sigma_mm * np.sqrt(3), color="k", ls="--", lw=1, label="noise (√3 σ)")
    axes[2].set_xticks(x, ctx.labels, fontsize=7)
    axes[2].set_ylabel("RMS (mm)")
    axes[2].legend(fontsize=7)
    return save(fig, path)


def gap_steps(diag, path) -> Path:
    """The gap after each adopted effect, with the noise floor."""
    names = ["rigid model"] + [f"{s.name}\n{_short_where(s.where)}" for s in diag.steps]
    gaps = [diag.gap_before] + [s.gap_after for s in diag.steps]
    fig = figure(figsize=(1.6 + 1.3 * len(names), 3.4))
    ax = fig.subplots()
    ax.bar(range(len(names)), gaps, color=["0.6"] + ["C0"] * len(diag.steps))
    ax.axhline(diag.noise_floor, color="C3", ls="--", label=f"noise floor {diag.noise_floor:.3g} mm")
    for i, g in enumerate(gaps):
        ax.text(i, g, f"{g:.3g}", ha="center", va="bottom", fontsize=8)
    ax.set_xticks(range(len(names)), names, fontsize=7)
    ax.set_ylabel("gap: RMS 3-D marker error (mm)")
    ax.legend(fontsize=8)
    return save(fig, path)


def _short_where(where: dict) -> str:
    """The marker(s), else the joint or segment, of an effect: what a bar of the gap-per-step figure names."""
    for key in ("markers", "joint", "segment"):
        v = where.get(key)
        if v:
            v = list(v) if isinstance(v, (list, tuple)) else [v]
            return ", ".join(map(str, v[:3])) + (" ..." if len(v) > 3 else "")
    return ""


def evidence(step, path, first_frame: int = 0, where: dict | None = None) -> Path:
    """One effect's evidence (:func:`evidence_figure`) written to `path`."""
    return save(evidence_figure(step, first_frame, where), path)


def evidence_svgs(diag) -> list:
    """(caption, SVG text) of each adopted effect's evidence figure, in the order adopted: what the HTML page
    of ``diagnose --report`` shows under its effects."""
    out = []
    for k, step in enumerate(diag.steps, 1):
        if step.evidence:
            where = diag.numbered(step.where)
            out.append((f"{k}. {step.name}: {where_text(where)}", svg_text(evidence_figure(step, diag.first_frame, where))))
    return out


def evidence_figure(step, first_frame: int = 0, where: dict | None = None):
    """One effect's evidence, drawn by the kind its evidence dictionary names: a Figure. An axis of frames
    (row indices in the evidence) is drawn in the file's numbering, its first row numbered `first_frame`;
    `where` (default the step's) is what the title names."""
    ev = step.evidence
    fig = figure(figsize=(7, 3.6))
    ax = fig.subplots()
    kind = ev.get("kind", "series")
    by_frame = ev.get("x_label") == "frame"
    shift = first_frame if by_frame else 0
    x, y, after = np.asarray(ev.get("x")) + shift, ev.get("y"), ev.get("y_after")
    if kind == "scatter":
        ax.plot(x, np.asarray(y), ".", ms=2, alpha=0.5, label="before")
        if after is not None:
            ax.plot(x if np.size(after) == np.size(x) else shift + np.arange(np.size(after)), np.asarray(after), ".",
                    ms=2, alpha=0.5, label="after")
    elif kind == "series3":
        y = np.asarray(y)
        for d, c in enumerate("xyz"):
            ax.plot(x, y[:, d], lw=0.8, label=f"{c} before")
        if after is not None:
            ax.plot(x, np.linalg.norm(np.asarray(after), axis=1), "k", lw=0.8, label="|after|")
    else:
        ax.plot(x, np.asarray(y), lw=0.8, label="before")
        if after is not None:
            ax.plot(x, np.asarray(after), lw=0.8, label="after / alternative")
    for f in ev.get("mark", [])[:200]:
        ax.axvline(f + shift, color="C3", lw=0.6, alpha=0.6)
    if "span" in ev:
        ax.axvspan(ev["span"][0] + shift, ev["span"][1] + shift, color="C3", alpha=0.15, label="span")
    ax.set_xlabel(FRAME_LABEL if by_frame else ev.get("x_label", ""))
    ax.set_ylabel(ev.get("y_label", ""), fontsize=8)
    ax.set_title(f"{step.name}: {where_text(step.where if where is None else where)}\ngap {step.gap_before:.3g} → {step.gap_after:.3g} mm",
                 fontsize=9)
    ax.legend(fontsize=7)
    return fig


def write_all(diag, directory) -> list:
    """Every figure of `diag` into `directory` (created); the paths written."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = [residual_map(diag, out / "residuals.png"), gap_steps(diag, out / "gap_per_step.png")]
    for k, step in enumerate(diag.steps, 1):
        if step.evidence:
            paths.append(evidence(step, out / f"evidence_{k}_{step.name}.png", diag.first_frame,
                                  diag.numbered(step.where)))
    return paths
