"""The documentation site builds with no warning (`mkdocs build --strict`), every internal link
and image of every page resolves, every image in docs/ is used by some page, and the home page
and a tutorial look like pages in headless Chromium (screenshots not blank)."""

from __future__ import annotations

import os
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHOTS = ("index.html", "tutorials/first-calibration.html")


class _Refs(HTMLParser):
    """The href/src of a page's links and images, and its element ids."""

    def __init__(self) -> None:
        super().__init__()
        self.refs: list[tuple[str, str]] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if a.get("id"):
            self.ids.add(a["id"])
        if tag == "a" and a.get("href"):
            self.refs.append(("link", a["href"]))
        if tag == "img" and a.get("src"):
            self.refs.append(("image", a["src"]))


def _parse(page: Path) -> _Refs:
    refs = _Refs()
    refs.feed(page.read_text(encoding="utf-8"))
    return refs


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    try:
        import mkdocs  # noqa: F401
    except ImportError:
        if os.environ.get("CI") == "true":
            pytest.fail("mkdocs is not installed: the docs extra is part of .[dev]")
        pytest.skip("the docs extra is not installed (pip install -e '.[docs]')")
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1",
           "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)}
    build = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)], cwd=ROOT,
                           env=env, capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, f"mkdocs build --strict failed:\n{build.stderr[-4000:]}"
    warnings = [line for line in build.stderr.splitlines() if line.startswith(("WARNING", "ERROR"))]
    assert not warnings, "\n".join(warnings)
    return out


def test_every_internal_link_and_image_resolves(site):
    pages = sorted(site.rglob("*.html"))
    assert len(pages) > 40
    ids = {page: _parse(page).ids for page in pages}
    broken = []
    for page in pages:
        if page.name == "404.html":  # served for any missing path: its links are site-absolute
            continue
        for kind, ref in _parse(page).refs:
            url = urlsplit(ref)
            if url.scheme or url.netloc or ref.startswith(("mailto:", "javascript:")):
                continue  # outside the site
            target = (page.parent / unquote(url.path)).resolve() if url.path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.is_file():
                broken.append(f"{page.relative_to(site)}: {kind} {ref}")
            elif url.fragment and target.suffix == ".html" and unquote(url.fragment) not in ids.get(target, set()):
                broken.append(f"{page.relative_to(site)}: {kind} {ref} (no such anchor)")
    assert not broken, "\n".join(broken)


def test_every_image_in_docs_is_used_and_the_reference_is_generated(site):
    used = set()
    for page in site.rglob("*.html"):
        for kind, ref in _parse(page).refs:
            if kind == "image" and not urlsplit(ref).scheme:
                used.add((page.parent / unquote(urlsplit(ref).path)).resolve())
    images = {(site / p.relative_to(ROOT / "docs")).resolve() for p in (ROOT / "docs").glob("*.png")}
    assert not sorted(images - used), f"images in docs/ used by no page: {sorted(images - used)}"
    cli = (site / "reference" / "cli.html").read_text(encoding="utf-8")
    assert "gyrobench line run" in cli and "--station" in cli
    procedures = (site / "reference" / "procedures.html").read_text(encoding="utf-8")
    assert "theta_tau_deg" in procedures and "record_s" in procedures
    assert "bench.analysis.damping.fit_free_decay" in (site / "reference" / "api-analysis.html").read_text()


def _chromium() -> str | None:
    exe = Path("/usr/bin/chromium")
    if exe.is_file():
        return str(exe)
    from bench.reporting.browser import chromium

    return chromium()


@pytest.mark.parametrize("page", SHOTS)
def test_pages_render_in_headless_chromium(site, page, tmp_path):
    """A screenshot of the page (1280 x 900) in Debian's headless Chromium is not blank: the theme's
    header, the navigation and the text are drawn."""
    exe = _chromium()
    if exe is None:
        if os.environ.get("CI") == "true":
            pytest.fail("chromium is not installed (.ci/run installs Debian's chromium)")
        pytest.skip("chromium is not installed")
    np = pytest.importorskip("numpy")
    from PIL import Image

    png = tmp_path / (page.replace("/", "_") + ".png")
    profile = tmp_path / "profile"
    shot = subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                           "--no-first-run", "--disable-component-update", "--disable-sync", "--hide-scrollbars",
                           f"--user-data-dir={profile}", "--window-size=1280,900", f"--screenshot={png}",
                           (site / page).as_uri()], capture_output=True, text=True, timeout=180)
    assert shot.returncode == 0 and png.is_file(), f"chromium made no screenshot: {shot.stderr[-2000:]}"
    if os.environ.get("GYROBENCH_DOCS_SHOTS"):  # keep it to look at
        Path(os.environ["GYROBENCH_DOCS_SHOTS"]).mkdir(parents=True, exist_ok=True)
        png.replace(Path(os.environ["GYROBENCH_DOCS_SHOTS"]) / png.name)
        png = Path(os.environ["GYROBENCH_DOCS_SHOTS"]) / png.name
    with Image.open(png) as im:
        rgb = np.asarray(im.convert("RGB")).astype(int)
    assert rgb.shape[:2] == (900, 1280)
    background = np.median(rgb.reshape(-1, 3), axis=0)
    drawn = (np.abs(rgb - background).sum(axis=2) > 60).mean()
    assert drawn > 0.03, f"{page}: only {drawn:.1%} of the screenshot differs from the background"
    header = rgb[:48].reshape(-1, 3).mean(axis=0)
    assert header[2] > header[0] + 30, f"{page}: the theme's (indigo) header is not drawn: mean {header}"
