"""A report page in Debian's headless Chromium: the DOM after load and the console messages (the
report test's check), and a full-page screenshot (docs/make_report_screenshots.py)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

WIDTH_PX = 1280


def chromium() -> str | None:
    """The Chromium executable on PATH (Debian: chromium), or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def _flags(profile: Path) -> list[str]:
    exe = chromium()
    if exe is None:
        raise FileNotFoundError("Debian's chromium is not installed (apt-get install chromium)")
    return [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0", "--hide-scrollbars"]


def load(page: Path, profile: Path) -> tuple[str, list[str]]:
    """(DOM after load, console messages) of a page."""
    run = subprocess.run(_flags(profile) + ["--dump-dom", page.as_uri()], capture_output=True, text=True,
                         timeout=120)
    if run.returncode != 0:
        raise RuntimeError(f"chromium exited {run.returncode}: {run.stderr[-2000:]}")
    return run.stdout, [line for line in run.stderr.splitlines() if ":CONSOLE" in line]


def screenshot(page: Path, png: Path, profile: Path, *, height_px: int = 4000, full_page: bool = False) -> Path:
    """A screenshot of the page, WIDTH_PX wide; full_page: the whole page (taken tall, then the
    empty margin under the page's end cut off)."""
    size = f"--window-size={WIDTH_PX},{30000 if full_page else height_px}"
    shot = subprocess.run(_flags(profile) + [f"--screenshot={png}", size, page.as_uri()], capture_output=True,
                          text=True, timeout=180)
    if shot.returncode != 0 or not png.is_file():
        raise RuntimeError(f"chromium made no screenshot: {shot.stderr[-2000:]}")
    if full_page:
        _crop_bottom(png)
    return png


def _crop_bottom(png: Path, margin_px: int = 24) -> None:
    """Cut the uniform background under the page's last content row."""
    import numpy as np
    from PIL import Image

    with Image.open(png) as im:
        rgb = np.asarray(im.convert("RGB"))
        rows = np.nonzero((rgb != rgb[-1, 0]).any(axis=(1, 2)))[0]
        bottom = min(len(rgb), int(rows[-1]) + margin_px) if len(rows) else len(rgb)
        im.crop((0, 0, rgb.shape[1], bottom)).save(png, optimize=True)
