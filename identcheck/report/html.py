"""One self-contained HTML page per run (``fit --report OUT.html``, ``diagnose --report OUT.html``): the skeleton
with its fitted joints in 3-D (drag to turn it, a slider and a play button to go through the trial), each
marker's residual against the noise, every joint's verdict, intervals and geometry, and (diagnose) the effects
with the gap each one closed and the evidence that named each one (the figures ``--plots`` writes, inline SVG).

The page loads nothing: its style, its data (a JSON block) and its small drawing script are inline, so it
opens offline and can be mailed as one file. Nothing here computes a result; it lays out the verb's JSON
document and the drawable scene of :func:`identcheck.fit.scene.fit_scene`. Once the script has drawn the first
frame it sets ``data-rendered="ok"`` on the body (``error: ...`` if the script failed), which the tests read
back from a headless browser.
"""
from __future__ import annotations

import datetime
import html
import json
import math
from pathlib import Path

from identcheck.io.atomic import atomic_write

VERDICT_COLOURS = {"determined": "#1a9850", "ambiguous": "#f39c12", "undetermined": "#d73027"}
SEGMENT_COLOURS = ("#4575b4", "#91bfdb", "#7b3294", "#c2a5cf", "#008837", "#a6dba0", "#e66101", "#fdb863",
                   "#5e3c99", "#b2abd2", "#0571b0", "#92c5de")

_STYLE = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px;color:#222;max-width:1200px}
h1{font-size:1.5em;margin-bottom:0}h2{font-size:1.2em;margin-top:1.6em;border-bottom:1px solid #ddd}
.sub{color:#666;margin-top:4px}table{border-collapse:collapse;margin:8px 0}
td,th{border:1px solid #ddd;padding:4px 8px;text-align:left;vertical-align:top;font-size:.92em}
th{background:#f4f4f4}.num{text-align:right;font-variant-numeric:tabular-nums}
.verdict{font-weight:600;color:#fff;padding:1px 6px;border-radius:3px}
.warn{background:#fff4e5;border-left:4px solid #f39c12;padding:6px 10px;margin:6px 0}
#viewer{display:flex;gap:16px;align-items:flex-start;flex-wrap:wrap}
canvas{border:1px solid #ccc;background:#fcfcfc;cursor:grab}
.controls{margin-top:6px}.legend span{display:inline-block;margin-right:12px}
figure.evidence{margin:12px 0}figure.evidence svg{max-width:100%;height:auto}
figcaption{font-size:.9em;color:#444}
.dot{display:inline-block;width:10px;height:10px;border-radius:50%;margin-right:4px;vertical-align:middle}
"""

_SCRIPT = r"""
(function(){
window.onerror=function(m){document.body.dataset.rendered='error: '+m;};
var S=JSON.parse(document.getElementById('scene-data').textContent);
var cv=document.getElementById('view'),g=cv.getContext('2d');
var slider=document.getElementById('frame'),lab=document.getElementById('frame-label');
var yaw=0.7,pitch=0.35,k=0,up=S.up,timer=null,drag=null;
var segs={};S.markers.forEach(function(m,i){var s=S.marker_segment[m];(segs[s]=segs[s]||[]).push(i);});
var jp={};S.joint_points.forEach(function(n,i){jp[n]=i;});
var cen=[],r=1;S.xyz.forEach(function(f,i){var pts=f.concat(S.joint_xyz[i]).filter(function(p){return p;});
 var c=[0,0,0];pts.forEach(function(p){for(var a=0;a<3;a++)c[a]+=p[a]/pts.length;});cen.push(c);
 pts.forEach(function(p){var d=Math.hypot(p[0]-c[0],p[1]-c[1],p[2]-c[2]);if(d>r)r=d;});});
function proj(p){var c=cen[k],x=p[0]-c[0],y=p[1]-c[1],z=p[2]-c[2];
 if(up==='y'){var t=y;y=-z;z=t;}
 var X=Math.cos(yaw)*x-Math.sin(yaw)*y,Y=Math.sin(yaw)*x+Math.cos(yaw)*y;
 var Z=Math.cos(pitch)*z-Math.sin(pitch)*Y;
 var s=0.45*Math.min(cv.width,cv.height)/r;return [cv.width/2+s*X,cv.height/2-s*Z];}
function line(a,b,col,w){if(!a||!b)return;var p=proj(a),q=proj(b);g.strokeStyle=col;g.lineWidth=w;
 g.beginPath();g.moveTo(p[0],p[1]);g.lineTo(q[0],q[1]);g.stroke();}
function dot(a,col,rad){if(!a)return;var p=proj(a);g.fillStyle=col;g.beginPath();g.arc(p[0],p[1],rad,0,6.2832);g.fill();}
function draw(){
 g.clearRect(0,0,cv.width,cv.height);var X=S.xyz[k],J=S.joint_xyz[k];
 S.joints.forEach(function(j){var pts=j.points.map(function(n){return J[jp[n]];});var ctr=pts[0];
  [j.parent,j.child].forEach(function(s){(segs[s]||[]).forEach(function(i){line(X[i],ctr,'#bbb',1);});});});
 Object.keys(segs).forEach(function(s){segs[s].forEach(function(i){dot(X[i],S.segment_colour[s],4);});});
 S.joints.forEach(function(j){var pts=j.points.map(function(n){return J[jp[n]];});var col=S.verdict_colour[j.name]||'#555';
  if(pts.length>1&&pts[0]&&pts[1]){var a=pts[0],b=pts[1],e=[];for(var q=0;q<3;q++)e.push(a[q]-(b[q]-a[q]));line(e,b,col,3);}
  dot(pts[0],col,6);if(pts[0]){var p=proj(pts[0]);g.fillStyle='#222';g.font='12px sans-serif';g.fillText(j.name,p[0]+8,p[1]-8);}});
 lab.textContent='frame '+S.frames[k]+' ('+(k+1)+' of '+S.frames.length+' shown)';
 document.body.dataset.rendered='ok';}
var most=-1;S.xyz.forEach(function(f,i){var n=f.filter(function(p){return p;}).length;if(n>most){most=n;k=i;}});
slider.max=S.frames.length-1;slider.value=k;slider.oninput=function(){k=+slider.value;draw();};
document.getElementById('play').onclick=function(){if(timer){clearInterval(timer);timer=null;this.textContent='play';return;}
 this.textContent='pause';timer=setInterval(function(){k=(k+1)%S.frames.length;slider.value=k;draw();},60);};
document.getElementById('up').onchange=function(){up=this.value;draw();};
cv.onmousedown=function(e){drag=[e.clientX,e.clientY];};window.onmouseup=function(){drag=null;};
window.onmousemove=function(e){if(!drag)return;yaw+=(e.clientX-drag[0])*0.01;pitch+=(e.clientY-drag[1])*0.01;
 pitch=Math.max(-1.5,Math.min(1.5,pitch));drag=[e.clientX,e.clientY];draw();};
document.getElementById('up').value=up;draw();
})();
"""


def _e(x) -> str:
    return html.escape(str(x))


def _num(x, digits: int = 3) -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{digits}g}"


def _up_axis(scene: dict) -> str:
    """The world's vertical, y or z (the view starts upright; the page lets the user switch): the one of the two
    along which the markers spread most within single frames, the body's length in a standing or walking
    subject (the spread over the whole trial would pick the direction of walking)."""
    spreads = [0.0, 0.0, 0.0]
    for frame in scene["xyz"]:
        pts = [p for p in frame if p]
        for a in range(3):
            if pts:
                vals = [p[a] for p in pts]
                spreads[a] += max(vals) - min(vals)
    return "y" if spreads[1] > spreads[2] else "z"


def bars_svg(rows: list, label: str, line: tuple | None = None) -> str:
    """Horizontal bars, one per ``(name, value, colour, tooltip)`` row (values in mm, drawn to the largest), each
    with its value; `line` = ``(value, text)`` adds a dashed reference line with its caption."""
    if not rows:
        return "<p>Nothing to draw.</p>"
    top = max([v for _, v, _, _ in rows] + ([1.5 * line[0]] if line else [])) or 1.0
    bar_h, left, width = 20, 150, 400
    h = bar_h * len(rows) + (40 if line else 16)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{left + width + 90}" height="{h}" role="img" '
           f'aria-label="{_e(label)}">']
    for i, (name, v, colour, tip) in enumerate(rows):
        y, w = 6 + i * bar_h, width * v / top
        out.append(f'<text x="{left - 6}" y="{y + 12}" text-anchor="end" font-size="12">{_e(name)}</text>'
                   f'<rect x="{left}" y="{y + 1}" width="{w:.1f}" height="{bar_h - 5}" fill="{colour}">'
                   f'<title>{_e(tip)}</title></rect>'
                   f'<text x="{left + w + 4:.1f}" y="{y + 12}" font-size="11">{v:.3g} mm</text>')
    if line:
        x = left + width * line[0] / top
        out.append(f'<line x1="{x:.1f}" x2="{x:.1f}" y1="4" y2="{h - 24}" stroke="#d73027" stroke-dasharray="4,3"/>'
                   f'<text x="{x:.1f}" y="{h - 8}" font-size="11" text-anchor="middle" fill="#d73027">{_e(line[1])}</text>')
    out.append("</svg>")
    return "".join(out)


def residual_svg(residual: dict, segment_of: dict, colours: dict, noise_mm: float | None) -> str:
    """Each marker's RMS residual (mm), coloured by segment, against the level noise alone would leave (σ√3 for a
    3-D distance)."""
    rows = [(m, v, colours.get(segment_of.get(m), "#888"), f"{m} ({segment_of.get(m)}): {v:.3g} mm")
            for m, v in residual.items() if v is not None]
    floor = noise_mm * math.sqrt(3) if noise_mm else None
    return bars_svg(rows, "RMS residual per marker", (floor, f"noise alone ≈ {floor:.2g} mm") if floor else None)


def _interval(ci) -> str:
    if not ci:
        return "–"
    lo, hi = ci
    return f"{lo:.1f} … not bounded" if hi is None else f"{lo:.1f} … {hi:.1f}"


def _geometry_cell(geom: dict | None) -> str:
    """The joint in its parent's technical frame, else (a parent with fewer than three markers) its child's."""
    side = geom and (geom.get("parent") or geom.get("child"))
    if not side:
        return "–"
    key = "centre" if "centre" in side else "axis_point"
    cov = side.get(f"{key}_covariance")
    se = [math.sqrt(max(cov[i][i], 0.0)) for i in range(3)] if cov else [None] * 3
    coords = ", ".join(f"{v:.1f}±{_num(s, 2)}" for v, s in zip(side[key], se))
    text = f"{key.replace('_', ' ')} ({coords}) mm in {_e(side.get('segment', 'parent'))}"
    if "axis_direction" in side:
        text += " ; axis (" + ", ".join(f"{v:.3f}" for v in side["axis_direction"]) + ")"
    return text


def joints_table(joints: dict) -> str:
    """Per joint: verdict, uncertainty, each marker distance with its 95 % interval, the geometry in the parent's
    technical frame and, when not determined, why and what would help."""
    rows = ["<table><tr><th>joint</th><th>type</th><th>verdict</th><th>uncertainty (mm)</th>"
            "<th>marker distances, mm (95 % interval)</th><th>geometry (technical frame, ± standard error)</th></tr>"]
    for name, j in joints.items():
        verdict = (j.get("practical") or {}).get("verdict", "undetermined")
        colour = VERDICT_COLOURS.get(verdict, "#555")
        ci = j.get("marker_distances_ci95") or {}
        place = (j.get("moving_centre") or {}).get("marker_distances_ci95")   # a centre moving with the angles
        dist = "<br>".join(f"{_e(m)}: {_num(d, 4)} ({_interval(ci.get(m))}"
                           + (f"; to its place over the trial {_interval(place.get(m))}" if place else "") + ")"
                           for m, d in (j.get("marker_distances") or {}).items())
        why = ""
        if verdict != "determined":
            p = j.get("practical") or {}
            why = f"<br><small>{_e(p.get('reason', ''))} {_e(p.get('motion_advice', ''))}</small>"
        alts = j.get("alternatives") or []
        if alts:
            why += f"<br><small>{len(alts)} other joint(s) fit as well</small>"
        rows.append(f"<tr><td>{_e(name)}</td><td>{_e(j.get('type', ''))}</td>"
                    f"<td><span class='verdict' style='background:{colour}'>{_e(verdict)}</span>{why}</td>"
                    f"<td class='num'>{_num(j.get('uncertainty_mm'))}</td><td>{dist}</td>"
                    f"<td>{_geometry_cell(j.get('geometry'))}</td></tr>")
    rows.append("</table>")
    return "".join(rows)


def effects_section(doc: dict) -> str:
    """Diagnose: the gap of the rigid model, each adopted effect with where it acts and the gap after it, as a
    table and as bars against the noise floor."""
    effects = doc.get("effects") or []
    parts = [f"<p>Gap of the rigid-joint model: <b>{_num(doc.get('gap_before'))} mm</b> (noise floor "
             f"{_num(doc.get('noise_floor_before'))} mm); after the effects: <b>{_num(doc.get('gap_after'))} mm</b> "
             f"(noise floor {_num(doc.get('noise_floor'))} mm).</p>"]
    refused = "".join(f"<li>{_e(r['name'])} ({_where_cell(r.get('where'))}): gain {_num(r.get('score'))}, but "
                      f"{_e(r['reason'])}</li>" for r in doc.get("not_adopted") or [])
    if refused:
        refused = ("<p>Seen but not adopted (they earn their parameters, but the joints would no longer be "
                   f"determined with them):</p><ul>{refused}</ul>")
    if not effects:
        parts.append("<p>No named effect earned its parameters" + (" and kept the joints determined.</p>" if refused
                                                                   else ".</p>") + refused)
        return "".join(parts)
    parts.append("<table><tr><th>#</th><th>effect</th><th>where</th><th>gap before (mm)</th><th>gap after (mm)</th></tr>")
    for k, e in enumerate(effects, 1):
        where = _where_cell(e.get("where"))
        parts.append(f"<tr><td>{k}</td><td>{_e(e['name'])}</td><td>{where}</td><td class='num'>"
                     f"{_num(e.get('gap_before'))}</td><td class='num'>{_num(e.get('gap_after'))}</td></tr>")
    parts.append("</table>")
    gaps = [("rigid model", doc.get("gap_before"))] + [(e["name"], e.get("gap_after")) for e in effects]
    parts.append(bars_svg([(name, v, "#4575b4", f"gap after {name}: {v:.3g} mm") for name, v in gaps if v is not None],
                          "gap after each effect", (doc["noise_floor"], "noise floor") if doc.get("noise_floor") else None))
    parts.append(refused)
    return "".join(parts)


def _where_cell(where: dict | None) -> str:
    """An effect's `where` as ``key: value; ...`` escaped for HTML, a list longer than six shortened."""
    return "; ".join(f"{_e(key)}: {_e(val if not isinstance(val, list) or len(val) <= 6 else str(val[:6]) + ' …')}"
                     for key, val in (where or {}).items())


def anatomical_section(anatomical: dict | None) -> str:
    """The fitted hip centres beside Harrington's and (given the leg length) Davis's regressions, in the ISB pelvis
    frame (``fit``'s ``anatomical``)."""
    if not anatomical or not anatomical.get("hips"):
        return ""
    pelvis = anatomical["pelvis"]
    rows = [f"<h2>Hip centres against Harrington (2007) and Davis (1991)</h2><p>{_e(pelvis['frame'])}. Pelvis width "
            f"{_num(pelvis['width_mm'])} mm, depth {_num(pelvis['depth_mm'])} mm.</p><table><tr><th>joint</th>"
            "<th>side</th><th>functional centre (x, y, z)</th><th>Harrington 2007 (x, y, z)</th><th>distance (mm)</th>"
            "<th>Davis 1991 (x, y, z)</th><th>distance (mm)</th></tr>"]
    for name, h in anatomical["hips"].items():
        davis = h.get("davis_1991")
        rows.append(f"<tr><td>{_e(name)}</td><td>{_e(h['side'])}</td><td>"
                    + ", ".join(f"{v:.1f}" for v in h["functional_centre"]) + "</td><td>"
                    + ", ".join(f"{v:.1f}" for v in h["harrington_2007"])
                    + f"</td><td class='num'>{h['distance_mm']:.1f}</td><td>"
                    + (", ".join(f"{v:.1f}" for v in davis) if davis else "needs the leg length ([subject] in the model)")
                    + f"</td><td class='num'>{_num(h.get('davis_distance_mm'))}</td></tr>")
    rows.append("</table>")
    return "".join(rows)


def evidence_section(figures: list | None) -> str:
    """Diagnose: each adopted effect's evidence figure, (caption, SVG text) as drawn by
    :func:`identcheck.report.diagnose_figures.evidence_svgs`; None when matplotlib, which draws them, is missing."""
    if figures is None:
        return ("<p>The evidence figures are drawn with matplotlib, which is not installed: "
                "<code>pip install 'identcheck[plots]'</code>.</p>")
    if not figures:
        return ""
    return "<h3>Evidence for each effect</h3>" + "".join(
        f"<figure class='evidence'>{svg}<figcaption>{_e(caption)}</figcaption></figure>" for caption, svg in figures)


def render(kind: str, doc: dict, scene: dict | None, title: str, version: str = "", figures: list | None = ()) -> str:
    """The page's HTML text. `kind`: ``fit`` or ``diagnose``; `doc`: that verb's JSON document; `scene`:
    :func:`identcheck.fit.scene.fit_scene` output, or None (no 3-D view, e.g. no whole-tree fit); `figures`
    (diagnose): the effects' evidence as (caption, SVG text), none by default, None when matplotlib is missing."""
    joints = doc.get("joints") or {}
    noise = doc.get("noise") or {}
    sigma = noise.get("sigma_mm") if isinstance(noise, dict) else None
    if sigma is None:
        sigma = doc.get("noise_sigma_mm")
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{_e(title)}</title>"
             f"<style>{_STYLE}</style></head><body data-rendered='pending'>",
             f"<h1>identcheck {_e(kind)}</h1><div class='sub'>{_e(title)} · identcheck {_e(version)} · "
             f"{datetime.datetime.now().strftime('%Y-%m-%d %H:%M')}</div>"]
    verdicts = [(j.get("practical") or {}).get("verdict", "undetermined") for j in joints.values()]
    counts = ", ".join(f"{verdicts.count(v)} {v}" for v in VERDICT_COLOURS if verdicts.count(v))
    parts.append(f"<p>{len(joints)} joint(s): {_e(counts)}. Noise: {_num(sigma)} mm per coordinate"
                 + (f", lag-1 correlation {_num(noise['correlation']['lag1'], 2)}"
                    if isinstance(noise, dict) and noise.get("correlation") else "") + ".</p>")
    for w in doc.get("warnings") or []:
        parts.append(f"<div class='warn'>{_e(w['message'] if isinstance(w, dict) else w)}</div>")
    if scene is not None:
        colours = {s: SEGMENT_COLOURS[i % len(SEGMENT_COLOURS)]
                   for i, s in enumerate(dict.fromkeys(scene["marker_segment"].values()))}
        data = dict(scene, segment_colour=colours, up=_up_axis(scene),
                    verdict_colour={n: VERDICT_COLOURS.get((j.get("practical") or {}).get("verdict"), "#555")
                                    for n, j in joints.items()})
        legend = "".join(f"<span><i class='dot' style='background:{c}'></i>{_e(s)}</span>" for s, c in colours.items())
        legend += "".join(f"<span><i class='dot' style='background:{c}'></i>joint {_e(v)}</span>"
                          for v, c in VERDICT_COLOURS.items())
        parts.append("<h2>Skeleton and fitted joints</h2><div id='viewer'><div><canvas id='view' width='640' "
                     "height='480' aria-label='3-D view of the markers and fitted joints'></canvas>"
                     "<div class='controls'><button id='play'>play</button> <input id='frame' type='range' min='0' "
                     "value='0' style='width:420px'> <span id='frame-label'></span> · up <select id='up'>"
                     "<option value='z'>z</option><option value='y'>y</option></select></div>"
                     f"<div class='legend'>{legend}</div><small>Drag to turn; the view follows the "
                     "subject (centred on each frame's points). Hinge axes drawn as thick lines; grey lines join each "
                     "joint to its segments' markers.</small></div>"
                     f"<div><h3>Residual per marker (RMS, mm)</h3>"
                     f"{residual_svg(scene['residual_rms_mm'], scene['marker_segment'], colours, sigma)}</div></div>")
        payload = json.dumps(data, allow_nan=False).replace("</", "<\\/")
        parts.append(f"<script type='application/json' id='scene-data'>{payload}</script>")
    if kind == "diagnose":
        parts.append("<h2>Effects</h2>" + effects_section(doc) + evidence_section(figures))
    parts.append("<h2>Joints</h2>" + joints_table(joints))
    parts.append(anatomical_section(doc.get("anatomical")))
    if kind == "fit":
        parts.append("<p><small>Verdicts: <b>determined</b> — unique, every marker distance's 95 % interval within "
                     "±10 mm; <b>ambiguous</b> — other joints explain the trial as well; <b>undetermined</b> — the "
                     "motion or the markers leave the joint free. Uncertainty: the largest standard error of a marker "
                     "distance.</small></p>")
    if scene is not None:
        parts.append(f"<script>{_SCRIPT}</script>")
    else:
        parts.append("<script>document.body.dataset.rendered='ok';</script>")
    parts.append("</body></html>")
    return "".join(parts)


def write_html(path, kind: str, doc: dict, scene: dict | None, title: str, version: str = "",
               figures: list | None = ()) -> Path:
    """Write the page to `path` (see :func:`render`); returns the path."""
    path = Path(path)
    atomic_write(path, render(kind, doc, scene, title, version, figures))
    return path
