"""``--report OUT.html``: one page that loads nothing from outside, holds the fit's own numbers (the 3-D scene's
joint centres where the simulator put them, in the file's frame numbering), and renders in a real browser."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from identcheck import cli
from identcheck.simulate.rigid import load_truth

ROOT = Path(__file__).resolve().parents[2]
LEG = str(ROOT / "examples" / "leg.toml")


class _Page(HTMLParser):
    """Tags with their attributes, the scene's JSON and the text, as a browser would parse them."""

    def __init__(self):
        super().__init__()
        self.tags, self.scene, self.text, self._in_scene = [], None, [], False

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))
        self._in_scene = tag == "script" and dict(attrs).get("id") == "scene-data"

    def handle_endtag(self, tag):
        self._in_scene = False

    def handle_data(self, data):
        if self._in_scene:
            self.scene = json.loads(data)
        else:
            self.text.append(data)


def _parse(path) -> _Page:
    page = _Page()
    page.feed(Path(path).read_text(encoding="utf-8"))
    return page


@pytest.fixture(scope="module")
def leg_report(tmp_path_factory):
    """fit --frames 50:250 --report on a simulated leg, with its truth and JSON."""
    tmp = tmp_path_factory.mktemp("report")
    trial, truth, page = tmp / "leg.trc", tmp / "truth.json", tmp / "leg.html"
    assert cli.main(["simulate", LEG, "--out", str(trial), "--truth", str(truth), "--seed", "7", "--noise-mm", "0.5",
                     "--frames", "300"]) == 0
    code = cli.main(["fit", LEG, str(trial), "--frames", "50:250", "--report", str(page)])
    return code, page, load_truth(truth)


def test_the_fit_page_loads_nothing_and_holds_the_fits_numbers(leg_report):
    code, page, truth = leg_report
    assert code in (0, 1) and page.exists()
    p = _parse(page)
    for tag, attrs in p.tags:                      # nothing fetched: no src, no stylesheet link, no remote href
        assert "src" not in attrs, (tag, attrs)
        assert not (tag == "link" and attrs.get("rel") == "stylesheet"), attrs
        assert not str(attrs.get("href", "")).startswith(("http:", "https:", "//")), attrs
    s = p.scene
    assert s["frames"][0] == 50 and s["frames"][-1] == 250 and len(s["xyz"]) == len(s["frames"])
    assert [j["name"] for j in s["joints"]] == ["hip_r", "knee_r", "ankle_r"]
    assert set(s["residual_rms_mm"]) == set(s["markers"])
    assert all(0 < v < 3 for v in s["residual_rms_mm"].values())          # 0.5 mm noise: ~0.87 mm in 3-D
    col = s["joint_points"].index("hip_r.centre")
    rows = np.array(s["frames"]) - 1                                       # TRC frame f is row f - 1
    got = np.array([f[col] for f in s["joint_xyz"]])
    assert np.max(np.linalg.norm(got - truth.centre_world("hip_r")[rows], axis=1)) < 2.5
    text = " ".join(p.text)
    for joint in ("hip_r", "knee_r", "ankle_r"):
        assert joint in text
    svg_bars = [a for t, a in p.tags if t == "rect"]
    assert len(svg_bars) == len(s["markers"])


def test_a_diagnose_page_shows_each_effect_and_the_gap(tmp_path, capsys):
    model = str(ROOT / "examples" / "diagnose_leg.toml")
    trial, page = tmp_path / "leg.trc", tmp_path / "d.html"
    assert cli.main(["simulate", model, "--out", str(trial), "--seed", "2", "--noise-mm", "0.5", "--frames", "300",
                     "--effect", "marker_slip"]) == 0
    capsys.readouterr()
    cli.main(["diagnose", model, str(trial), "--json", "--report", str(page)])
    doc = json.loads(capsys.readouterr().out)
    text = " ".join(_parse(page).text)
    assert "Effects" in text and f"{doc['gap_before']:.3g} mm" in text
    assert doc["effects"]                                          # the slip is found, and shown
    for e in doc["effects"]:
        assert e["name"] in text
    # each effect's evidence figure, inline: an <svg> in a <figure> captioned by the effect, its axes labelled
    source = page.read_text(encoding="utf-8")
    figures = re.findall(r"<figure class='evidence'>(.*?)</figure>", source, flags=re.S)
    assert len(figures) == len(doc["effects"])
    for e, fig in zip(doc["effects"], figures):
        assert fig.lstrip().startswith("<svg") and "</svg>" in fig
        caption = re.search(r"<figcaption>(.*?)</figcaption>", fig).group(1)
        assert e["name"] in caption
    assert "frame" in figures[0]                                   # a slip's evidence is drawn against frames


def test_without_matplotlib_the_page_says_which_extra_draws_the_evidence():
    from identcheck.report.html import evidence_section

    assert "identcheck[plots]" in evidence_section(None) and evidence_section([]) == ""


@pytest.mark.parametrize("name", ["out.txt", "SAME_AS_TRIAL"])
def test_a_report_that_is_not_html_or_would_overwrite_the_trial_is_refused_first(tmp_path, capsys, name):
    trial = tmp_path / "leg.trc"
    assert cli.main(["simulate", LEG, "--out", str(trial), "--frames", "50"]) == 0
    before = trial.read_bytes()
    target = trial if name == "SAME_AS_TRIAL" else tmp_path / name
    capsys.readouterr()
    assert cli.main(["fit", LEG, str(trial), "--report", str(target)]) == 2
    err = capsys.readouterr().err
    assert "--report" in err and str(target) in err
    assert trial.read_bytes() == before


def _browser():
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


@pytest.mark.skipif(_browser() is None, reason="no Chromium on this machine (Debian: apt install chromium)")
def test_the_page_renders_in_a_headless_browser(leg_report, tmp_path):
    """Headless Chromium runs the page's script: it draws the first frame and marks the body rendered, with no
    script error; the frame label names the file's first frame."""
    _, page, _ = leg_report
    out = subprocess.run([_browser(), "--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={tmp_path}",
                          "--virtual-time-budget=3000", "--dump-dom", page.resolve().as_uri()],
                         capture_output=True, text=True, timeout=120)
    dom = out.stdout
    assert re.search(r"<body[^>]*data-rendered=\"ok\"", dom), (dom[:500], out.stderr[-2000:])
    assert "frame 50 (1 of" in dom


def test_the_scene_draws_no_joint_in_a_frame_where_no_marker_was_seen():
    """A frame with every marker occluded: the fit only bridges it, so the scene leaves its joints out (None);
    the other frames keep them, in the file's numbering."""
    import warnings

    from identcheck.fit.scene import fit_scene
    from identcheck.fit.workflow import fit_trial
    from identcheck.io.model import Model
    from identcheck.simulate.rigid import simulate

    model = Model.from_toml(LEG)
    sim = simulate(model, n_frames=120, noise_mm=0.5, seed=3)
    got = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit_trial(model, sim.trial, on_fit=lambda t, fit, offset: got.update(fit=fit, trial=t))
    fit = got["fit"]
    data = got["trial"].select(fit.chain.labels).as_array()
    data[0] = np.nan
    scene = fit_scene(fit, data, np.arange(120) + 10, max_frames=120)
    assert scene["frames"][:2] == [10, 11]
    assert all(p is None for p in scene["joint_xyz"][0]) and all(p is None for p in scene["xyz"][0])
    assert all(p is not None for p in scene["joint_xyz"][1])


@pytest.mark.parametrize("adopted", [0, 1])
def test_an_effect_seen_but_not_adopted_is_on_the_page_with_its_reason(adopted):
    """The diagnose page lists the effects refused because the joints would no longer be determined, with where they
    act and why, whether or not another effect was adopted; a page without any says nothing of them."""
    from identcheck.report.html import effects_section

    refused = {"name": "soft_tissue", "where": {"segment": "pelvis", "markers": ["RASI", "<LASI>"]}, "score": 7362.2,
               "joint": "hip_l", "worst_sd_mm": 22.1, "reason": "hip_l would be determined to 22 mm"}
    effects = [{"name": "outliers", "where": {"count": 3}, "gap_before": 2.0, "gap_after": 1.5}][:adopted]
    doc = {"gap_before": 2.0, "gap_after": 1.5, "noise_floor": 0.8, "noise_floor_before": 0.8, "effects": effects,
           "not_adopted": [refused]}
    page = effects_section(doc)
    assert "Seen but not adopted" in page and "hip_l would be determined to 22 mm" in page
    assert "pelvis" in page and "&lt;LASI&gt;" in page and "<LASI>" not in page
    assert "Seen but not adopted" not in effects_section({**doc, "not_adopted": []})
