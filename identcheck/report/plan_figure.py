"""Figure of a marker plan: the skeleton tree, joints coloured by verdict, marker counts on segments."""
from __future__ import annotations

from pathlib import Path

from identcheck.report.figure_io import figure as new_figure, save

COLOURS = {"identifiable": "#2e7d32", "local": "#f9a825", "not": "#c62828"}


def _layout(joints: dict, root: str) -> dict:
    """Segment -> (x, y): leaves spread along x, depth down y (a tidy tree)."""
    children: dict = {}
    for name, j in joints.items():
        children.setdefault(j["parent"], []).append(j["child"])
    pos, next_x = {}, [0.0]

    def place(seg, depth):
        kids = children.get(seg, [])
        if not kids:
            pos[seg] = (next_x[0], -depth)
            next_x[0] += 1.0
        else:
            xs = [place(k, depth + 1) for k in kids]
            pos[seg] = (sum(xs) / len(xs), -depth)
        return pos[seg][0]
    place(root, 0)
    return pos


def figure(plan, title: str = ""):
    """The plan's tree as a :class:`matplotlib.figure.Figure`: segments with their marker counts, joints
    coloured by verdict (identifiable, locally identifiable, not), balls round and hinges square.

    Parameters
    ----------
    plan : PlanResult
        What :func:`identcheck.plan.analysis.plan_model` returns (its joints, root and markers).
    title : str
        Default "marker plan".
    """
    from matplotlib.lines import Line2D

    joints, markers = plan.joints, plan.markers
    pos = _layout(joints, plan.root)
    width = max(6.0, 1.3 * (max(x for x, _ in pos.values()) + 1))
    fig = new_figure(figsize=(width, 1.6 * (1 - min(y for _, y in pos.values())) + 1.5))
    ax = fig.subplots()
    for name, j in joints.items():
        (x0, y0), (x1, y1) = pos[j["parent"]], pos[j["child"]]
        verdict = "identifiable" if j["identifiable"] else ("local" if j["local"] else "not")
        xm, ym = x1, y1 + 0.45                       # just above the child: labels never collide
        ax.plot([x0, xm, x1], [y0, ym, y1], color="#9e9e9e", lw=1.5, zorder=1)
        ax.scatter([xm], [ym], s=220, color=COLOURS[verdict], zorder=3,
                   marker="o" if j["type"] == "spherical" else "s", edgecolor="black")
        label = f"{name}\n{j['case']}"
        if j["candidates"] and j["candidates"] > 1:
            label += f" ×{j['candidates']}"
        ax.annotate(label, (xm, ym), xytext=(8, 0), textcoords="offset points", fontsize=7, va="center")
    for seg, (x, y) in pos.items():
        n = len(markers.get(seg, ()))
        ax.text(x, y, f"{seg}\n{n} marker{'s' if n != 1 else ''}", ha="center", va="center", fontsize=7,
                bbox=dict(boxstyle="round", fc="white", ec="#616161"), zorder=4)
    handles = [Line2D([], [], marker="o", ls="", color=c, markeredgecolor="black", label=l) for l, c in
               (("identifiable (unique)", COLOURS["identifiable"]), ("locally identifiable", COLOURS["local"]),
                ("not identifiable", COLOURS["not"]))]
    handles += [Line2D([], [], marker="o", ls="", color="white", markeredgecolor="black", label="spherical"),
                Line2D([], [], marker="s", ls="", color="white", markeredgecolor="black", label="revolute")]
    ax.legend(handles=handles, loc="lower left", fontsize=7, frameon=False, ncol=5, bbox_to_anchor=(0, -0.12))
    ax.set_title(title or "marker plan", fontsize=9)
    ax.axis("off")
    return fig


def draw(plan, path, title: str = "") -> Path:
    """Write the plan figure (:func:`figure`) to ``path`` (PNG/SVG by extension); returns the path."""
    return save(figure(plan, title), path, dpi=130)
