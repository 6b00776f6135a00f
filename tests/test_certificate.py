"""The unit's calibration certificate (bench/line/certificate.py): every identified coefficient
with its expanded uncertainty (each side when asymmetric), the limits, rule and outcome of every
measurement, the traceability and signature lines; the page in headless Chromium and as a PDF."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

from cert_record import RECORD
from needs import need

from bench.line.certificate import certificate_section, expanded_u, render_html, write_certificate

DOCS = Path(__file__).resolve().parent.parent / "docs"


def _text(html: str) -> str:
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html))


def test_expanded_uncertainty_is_given_each_side_when_asymmetric():
    assert expanded_u(9.1e-5, [8.9e-5, 9.4e-5]) == "− 2.0e-6 / + 3.0e-6"
    assert expanded_u(25.2, [24.9, 25.5]) == "± 0.30"
    assert expanded_u(10.3, None) == "—"


def test_certificate_lists_coefficients_limits_rules_outcomes_and_traceability():
    html = render_html(RECORD)
    text = _text(html)
    assert "Calibration certificate" in text and "HRG-2611-0042" in text and "L2611" in text
    # the identified coefficients with U, the register they load
    for name, u, reg in (("delta_inv_tau_per_s", "− 2.0e-6 / + 3.0e-6", "TRIM_DRIFT_D_PER_S"),
                         ("theta_tau_deg", "− 0.30 / + 0.40", "TRIM_DRIFT_THETA_TAU_DEG"),
                         ("split_hz", "− 2.0e-4 / + 3.0e-4", "TRIM_SPLIT_HZ"),
                         ("theta_w_deg", "—", "TRIM_SPLIT_THETA_DEG")):
        row = re.search(rf"<tr><td>{name}<br>.*?</tr>", html, re.S).group(0)
        assert u in _text(row) and reg in row, (name, _text(row))
    # every measurement with its limits, rule and outcome (the marginal one straddles 0.5)
    for m in RECORD["measurements"]:
        assert f"<td>{m['name']}<br>" in html
    row = _text(re.search(r"<tr><td>drift_after_dph<br>.*?</tr>", html, re.S).group(0))
    assert "≤ 0.5" in row and "guard-band" in row and "MARGINAL" in row and "[0.31, 0.62]" in row
    assert "ILAC G8: PASS when the whole 95 % interval lies inside the limits" in text
    assert "value only" in text
    assert "7 pass, 1 marginal, 0 fail" in text
    # traceability and signatures
    for run in RECORD["runs"]:
        assert run["run_id"] in text and run["sha256"] in text and run["raw_file"] in text
    assert "gyrobench 0.1.0" in text and "Tested by (signature) ada, operator" in text
    assert "Approved by" in text and "calibrated 2026-11-23" in text


def test_section_for_the_run_report_is_the_body_alone():
    part = certificate_section(RECORD)
    assert part.lstrip().startswith("<section class=\"certificate\">") and "<html" not in part


def test_certificate_pdf(tmp_path):
    html, pdf = write_certificate(RECORD, tmp_path / "cert.html", pdf=True)
    assert html.read_text().startswith("\n<!doctype html>") or "<!doctype html>" in html.read_text()[:40]
    data = pdf.read_bytes()
    assert data[:5] == b"%PDF-" and len(data) > 5_000


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def test_certificate_in_headless_chromium(tmp_path):
    """No console message and every table in the DOM.  With GYROBENCH_DOCS_SCREENSHOTS=1 a
    screenshot replaces docs/certificate.png."""
    need(_chromium() is not None, "Debian's chromium is not installed (apt-get install chromium)")
    page = write_certificate(RECORD, tmp_path / "cert.html")[0]
    flags = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={tmp_path / 'profile'}", "--enable-logging=stderr", "--v=0", "--hide-scrollbars"]
    run = subprocess.run(flags + ["--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert [line for line in run.stderr.splitlines() if ":CONSOLE" in line] == []
    dom = run.stdout
    for cls in ("identity", "coefficients", "measurements", "runs"):
        assert f'<table class="{cls}">' in dom
    assert dom.count('class="MARGINAL"') >= 1 and "Approved by" in dom
    if os.environ.get("GYROBENCH_DOCS_SCREENSHOTS") == "1":
        shot = tmp_path / "certificate.png"
        r = subprocess.run(flags + [f"--screenshot={shot}", "--window-size=1100,1500", page.as_uri()],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and shot.is_file(), r.stderr[-2000:]
        shutil.copy(shot, DOCS / "certificate.png")


def test_unit_documents_certificate_and_compensation_file(tmp_path):
    from bench.line.certificate import write_unit_documents
    from bench.line.compensation import load

    out = write_unit_documents(RECORD, tmp_path / "units")
    assert sorted(p.name for p in out.values()) == ["HRG-2611-0042-a1.certificate.html",
                                                     "HRG-2611-0042-a1.compensation.toml"]
    comp = load(out["compensation"])
    assert f"Compensation file id {comp.file_id():012x}" in out["certificate"].read_text()
    only_q = [m for m in RECORD["measurements"] if m["name"] == "q_factor"]
    mems = {**RECORD, "serial": "MEMS-1", "measurements": only_q}
    assert list(write_unit_documents(mems, tmp_path / "units")) == ["certificate"]  # no trims: no compensation file


def test_the_run_report_with_the_certificate_as_its_first_page(tmp_path):
    """A short table-spin run's report with the unit's certificate in the report's `certificate`
    block: the certificate comes before the report's heading, the report follows unchanged, and
    the PDF has the certificate on a page of its own."""
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from bench.recorder import open_run
    from bench.reporting import render_html as report_html
    from bench.reporting.unit_certificate import report_with_certificate
    from procedures import find_procedure

    station = SimStation("sim-hrg", seed=3).open()
    try:
        rec = Runner(station, runs_dir=tmp_path / "runs", duts=["HRG-2611-0042"]).run(
            find_procedure("table-spin"), {"rate_dps": 50.0, "hold_s": 0.5})
    finally:
        station.close()
    with open_run(rec.raw_file) as data:
        page = report_with_certificate(data, RECORD)
        plain = report_html(data)
    assert page.index('<section class="certificate">') < page.index("<h1>table-spin")
    assert page.count("<h1>") == plain.count("<h1>") + 1 and "Calibration certificate" in page
    assert "&lt;style&gt;" not in page and "<style>" in page.split('<section class="certificate">')[1]  # not escaped
    import weasyprint

    doc = weasyprint.HTML(string=page).render()
    first = doc.pages[0]._page_box.descendants()
    text = " ".join(getattr(b, "text", "") for b in first if getattr(b, "text", ""))
    assert "Calibration certificate" in text and "table-spin — run" not in text and len(doc.pages) >= 2


def test_measurements_without_limits_are_listed_apart():
    extra = {"name": "drift_before_dph", "procedure": "hrg-damping", "run_id": "r-damp", "value": 29.4,
             "unit": "deg/h", "interval": [28.2, 30.6], "limits": {"low": None, "high": None}, "rule": None,
             "outcome": "COMPLETE"}
    html = render_html({**RECORD, "measurements": RECORD["measurements"] + [extra]})
    decided, informative = html.split('<table class="informative">')
    assert "<td>drift_before_dph<br>" not in decided and "<td>drift_before_dph</td>" in informative
    assert "± 1.2" in _text(informative.split("</table>")[0])


def test_certificate_marks_simulated_product_limits_revision_and_conditions(tmp_path):
    """Issue 32: SIMULATED on a simulated station, product and limits revision, a MARGINAL's kind
    and reason, the trims' state; a failed unit gets a rejection report saying why; PDF too."""
    import copy

    from bench.line.certificate import pdf_available, render_html, write_unit_documents

    rec = copy.deepcopy(RECORD)
    rec.update(simulated=True, product="hrg-5500", limits_file="/x/hrg.toml", limits_sha256="ab12" * 16,
               trims={"written": False, "reason": "unit MARGINAL: trims are written for PASS units only"})
    drift = next(m for m in rec["measurements"] if m["name"] == "drift_after_dph")
    drift.update(condition="conditional pass", note="conditional pass: the value 0.45 is inside the limits")
    html = render_html(rec)
    assert "SIMULATED" in html and "hrg-5500" in html and "revision ab12ab12ab12" in html
    assert "conditional pass" in html and "the value 0.45 is inside the limits" in html
    assert "Calibration certificate" in html and "Rejection report" not in html
    assert "NOT written: unit MARGINAL: trims are written for PASS units only" in html
    real = render_html({**rec, "simulated": False})
    assert "SIMULATED" not in real
    rec["outcome"] = "FAIL"
    tau = next(m for m in rec["measurements"] if m["name"] == "tau_s")
    tau.update(outcome="FAIL", note="")
    html = render_html(rec)
    assert "<h1>Rejection report</h1>" in html and "Why the unit is rejected" in html
    if pdf_available():
        out = write_unit_documents(rec, tmp_path, pdf=True)
        assert out["certificate_pdf"].read_bytes()[:5] == b"%PDF-"
