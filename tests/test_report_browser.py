"""The HTML report in a real browser: self-contained, renders, has its sections.

Headless Chromium loads the report from a ``file://`` URL with networking disabled,
takes a screenshot (it must not be blank) and dumps the DOM (the headings must be
there).  Without a Chromium binary the browser tests skip — except in CI
(``CI=true``), where a missing browser is a failure: ``scripts/run-tests.sh``
installs it when it runs as root.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

from rotor_env.diagnosis import diagnose
from rotor_env.params import Crack, RotorParams
from rotor_env.simulator import simulate

HEADINGS = ("Summary", "Compare", "Where it fails", "Which effect is missing", "Before and after",
            "Bode and polar plots", "Orbits", "Waterfall", "Campbell diagram", "Parameter tracks")
#: the embedded figures, in the page's order (DiagnosisFigures.FIGURES holds them all)
FIGURES = ("compare", "residual", "order_map", "autocorrelation", "candidates", "before_after", "residual_after",
           "bode", "polar", "orbit", "waterfall", "campbell", "parameter_tracks")
PAGE_HEIGHT = 9000
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def _chromium() -> str:
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    if os.environ.get("CI") == "true":
        pytest.fail(f"no Chromium binary ({', '.join(BROWSERS)}) on PATH in CI: "
                    "install it (scripts/run-tests.sh does so as root: apt-get install chromium)")
    pytest.skip(f"no Chromium binary ({', '.join(BROWSERS)}) on PATH; "
                "install it with `apt-get install chromium` to run the browser checks")


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    """The walkthrough's case, shortened: a crack at t = 100 in a rotor with dry friction,
    run up twice as fast with half the samples."""
    params = RotorParams().replace(D=0.0, k30=0.0, k21=0.0, k12=0.0, k03=0.0, crack=Crack(100.0, 0.05))
    meas = simulate(params, t_end=160.0, dt=0.04, run_up=0.02, noise=5e-4, seed=1)
    res = diagnose(meas, ("unbalance", "viscous_damping", "structural_damping"))
    assert res.missing == ["asymmetry"]
    return res.report(tmp_path_factory.mktemp("report") / "report.html")


class _Refs(HTMLParser):
    """Collects every URL-valued attribute and the text of the h1/h2 headings."""

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[tuple[str, str, str]] = []
        self.headings: list[str] = []
        self._in: str | None = None

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if name in ("src", "href", "srcset", "poster", "data", "action", "formaction") and value is not None:
                self.urls.append((tag, name, value))
        if tag in ("h1", "h2"):
            self._in, self._text = tag, ""

    def handle_data(self, data):
        if self._in:
            self._text += data

    def handle_endtag(self, tag):
        if tag == self._in:
            self.headings.append(self._text.strip())
            self._in = None


def _parse(text: str) -> _Refs:
    p = _Refs()
    p.feed(text)
    p.close()
    return p


def test_report_is_self_contained(report):
    text = report.read_text(encoding="utf-8")
    refs = _parse(text)
    external = [(t, a, v[:60]) for t, a, v in refs.urls if not v.startswith(("data:", "#"))]
    assert not external, f"external references in the report: {external}"
    imgs = [v for t, a, v in refs.urls if t == "img" and a == "src"]
    assert len(imgs) == len(FIGURES) and all(v.startswith("data:image/png;base64,") for v in imgs)
    assert re.findall(r'<img alt="(\w+)"', text) == list(FIGURES)
    assert not re.search(r"<link\b|<script\b[^>]*\bsrc=|@import|url\(\s*['\"]?(?!data:)", text, re.I)
    assert [h for h in refs.headings if h in HEADINGS] == list(HEADINGS)


def _run(args: list[str], profile: Path) -> subprocess.CompletedProcess:
    cmd = [
        _chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--no-first-run", "--no-default-browser-check", "--hide-scrollbars",
        f"--user-data-dir={profile}", *args,
    ]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=180, check=False)


def test_report_renders_in_headless_chromium(report, tmp_path):
    url = report.resolve().as_uri()
    png = tmp_path / "shot.png"
    proc = _run([f"--screenshot={png}", f"--window-size=1200,{PAGE_HEIGHT}", url], tmp_path / "profile1")
    assert png.exists(), f"no screenshot (exit {proc.returncode}): {proc.stderr[-2000:]}"
    import matplotlib.image as mpimg

    img = mpimg.imread(png)[..., :3]  # floats in [0, 1]
    assert img.shape[:2] == (PAGE_HEIGHT, 1200)
    assert float(img.std()) > 0.05, "the screenshot is (nearly) one colour"
    colours = np.unique((img.reshape(-1, 3) * 255).astype(np.uint8), axis=0)
    assert len(colours) > 200, f"only {len(colours)} distinct colours: are the figures rendered?"
    # the embedded figures draw coloured (red/blue) curves and bars, not just black text
    rgb = img.reshape(-1, 3)
    saturated = (rgb.max(axis=1) - rgb.min(axis=1)) > 0.3
    assert saturated.mean() > 0.005, f"only {saturated.mean():.2%} coloured pixels"
    # the figures are spread down the page: every third of it carries ink, and the field views
    # (Bode ... parameter tracks, the lower part) draw colour too
    third = PAGE_HEIGHT // 3
    for part in (img[:third], img[third:2 * third], img[2 * third:]):
        assert (part.mean(axis=2) < 0.5).mean() > 0.002
    lower = img[third:].reshape(-1, 3)
    assert ((lower.max(axis=1) - lower.min(axis=1)) > 0.3).mean() > 0.005

    proc = _run(["--dump-dom", url], tmp_path / "profile2")
    assert proc.returncode == 0, proc.stderr[-2000:]
    dom = _parse(proc.stdout)
    for h in HEADINGS:
        assert h in dom.headings, f"heading {h!r} missing from the rendered page: {dom.headings}"
    assert "rotor-id diagnosis" in dom.headings
    assert "asymmetry" in proc.stdout and "added in round" in proc.stdout
