"""A unit's calibration certificate: its identity, the identified coefficients with their expanded
uncertainties U, each measurement against its limits with the decision rule and outcome, the
traceability (software version, run ids, raw-file checksums) and signature lines.

Built from a unit record dict (the line's schema) and its compensation (bench/line/compensation.py);
one HTML page (its own Jinja2 template, templates/certificate.html.j2) and the same page as a PDF
(WeasyPrint, as bench/reporting).  `certificate_section(...)` is the page's body alone, for the
run report's extra sections."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

from bench.numbers import DASH, limits, plain, sig, with_interval

from .compensation import COEFFICIENTS, Compensation, CompensationError, from_record

TEMPLATES = Path(__file__).with_name("templates")
RULE_WORDS = {
    "guard-band": "ILAC G8: PASS when the whole 95 % interval lies inside the limits, FAIL when it lies wholly "
               "outside, MARGINAL when it straddles a limit: a conditional pass when the value is inside the "
               "limits, a conditional fail when it is outside",
    "value": "value only: PASS when the value lies inside the limits (MARGINAL inside a marginal band near "
             "them); applies to a measurement without an interval",
}  # fmt: skip


DECIDING = ("PASS", "FAIL", "MARGINAL", "ERROR")  # outcomes a limit gave; COMPLETE: measured, no limit


def _f(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def expanded_u(value: Any, interval: Any) -> str:
    """U of a 95 % interval: '±U' when symmetric (to 2 significant digits), '−Ul / +Uh' when not, '—' without."""
    v = _f(value)
    if v is None or not interval or len(interval) != 2:
        return DASH
    lo, hi = _f(interval[0]), _f(interval[1])
    if lo is None or hi is None or hi < lo:
        return DASH
    u_lo, u_hi = v - lo, hi - v
    if math.isclose(u_lo, u_hi, rel_tol=0.02, abs_tol=1e-300):
        return f"± {sig(0.5 * (u_lo + u_hi), 2)}"
    return f"− {sig(u_lo, 2)} / + {sig(u_hi, 2)}"


def _u_sides(lo: float | None, hi: float | None) -> str:
    if lo is None or hi is None:
        return DASH
    if math.isclose(lo, hi, rel_tol=0.02, abs_tol=1e-300):
        return f"± {sig(0.5 * (lo + hi), 2)}"
    return f"− {sig(lo, 2)} / + {sig(hi, 2)}"


def _rule_key(rule: Any) -> str:
    text = str(rule or "").lower()
    if "g8" in text or "ilac" in text or "interval" in text or "guard" in text:
        return "guard-band"
    return "value" if text else ""


def certificate_number(record: dict[str, Any]) -> str:
    """A stable id: serial, attempt and 8 hex digits of the record's run ids and end time."""
    seed = "|".join([str(record.get("serial", "")), str(record.get("attempt", "")), str(record.get("ended_at", ""))]
                    + [str(r.get("run_id", "")) for r in record.get("runs") or ()])
    return f"{record.get('serial', '')}-{record.get('attempt', 1)}-{hashlib.sha256(seed.encode()).hexdigest()[:8]}"


def context(record: dict[str, Any], compensation: Compensation | None = None) -> dict[str, Any]:
    """Everything the certificate shows, as text."""
    if compensation is None:
        try:
            compensation = from_record(record)
        except CompensationError:
            compensation = None  # a unit without any trim coefficient (a MEMS sequence)
    rows = []
    rules = []
    for m in record.get("measurements") or ():
        value, interval = m.get("value"), m.get("interval")
        shown, ci = with_interval(value, interval)
        lim = m.get("limits") or {}
        key = _rule_key(m.get("rule"))
        if key and key not in rules:
            rules.append(key)
        rows.append({
            "name": m.get("name", ""), "procedure": m.get("procedure", ""), "value": shown, "interval": ci,
            "u": expanded_u(value, interval), "unit": m.get("unit", ""),
            "limits": limits(lim.get("low"), lim.get("high")), "rule": m.get("rule") or DASH,
            "outcome": m.get("outcome") or DASH, "run_id": m.get("run_id", ""),
            "condition": m.get("condition") or "", "note": m.get("note") or "",
            "decided": m.get("outcome") in DECIDING or lim.get("low") is not None or lim.get("high") is not None,
        })  # fmt: skip
    coeffs = []
    if compensation is not None:
        for c in compensation.coefficients.values():
            interval = None if c.u_low is None or c.u_high is None else [c.value - c.u_low, c.value + c.u_high]
            shown, _ = with_interval(c.value, interval)
            coeffs.append({"name": c.name, "doc": COEFFICIENTS[c.name].doc, "value": shown, "unit": c.unit,
                           "u": _u_sides(c.u_low, c.u_high), "register": c.register, "run_id": c.run_id,
                           "procedure": c.procedure})
    counts = {o: sum(1 for r in rows if r["outcome"] == o) for o in ("PASS", "MARGINAL", "FAIL", "ERROR")}
    outcome = record.get("outcome", "")
    rejected = outcome in ("FAIL", "ERROR", "ABORTED")
    limits_rev = str(record.get("limits_sha256") or "")[:12]
    trims = record.get("trims")
    if trims is None:
        trims_text = "not part of this sequence"
    elif trims.get("written"):
        trims_text = (f"written to the unit's NVM and read back equal (unit id {trims.get('unit_id')}, NVM CRC "
                      f"{trims.get('crc')}); file SHA-256 {trims.get('sha256')}")
    else:
        trims_text = "NOT written: " + str(trims.get("error") or trims.get("reason") or "")
    return {
        "title": "Rejection report" if rejected else "Calibration certificate",
        "rejected": rejected,
        "reasons": [r for r in rows if r["outcome"] in ("FAIL", "ERROR", "MARGINAL")],
        "abort_reason": record.get("abort_reason") or "",
        "simulated": bool(record.get("simulated")),
        "trims_text": trims_text,
        "number": certificate_number(record),
        "serial": record.get("serial", ""),
        "outcome": record.get("outcome", ""),
        "identity": [
            ("Serial", record.get("serial", "")), ("Lot", record.get("lot") or DASH),
            ("Product", record.get("product") or DASH),
            ("Limits", f"{Path(str(record.get('limits_file') or '')).name or DASH} (revision {limits_rev or DASH})"),
            ("Sequence", record.get("sequence", "")), ("Attempt", str(record.get("attempt", ""))),
            ("Station", record.get("station", "")), ("Operator", record.get("operator") or DASH),
            ("Started", record.get("started_at") or DASH), ("Ended", record.get("ended_at") or DASH),
        ],  # fmt: skip
        "software_version": record.get("software_version", ""),
        "measurements": [r for r in rows if r["decided"]],
        "informative": [r for r in rows if not r["decided"]],
        "counts": counts,
        "coefficients": coeffs,
        "compensation_id": f"{compensation.file_id():012x}" if compensation is not None else "",
        "rules": [(k, RULE_WORDS[k]) for k in rules],
        "runs": [{"run_id": r.get("run_id", ""), "procedure": r.get("procedure", ""), "outcome": r.get("outcome", ""),
                  "raw_file": r.get("raw_file") or DASH, "sha256": r.get("sha256") or DASH}
                 for r in record.get("runs") or ()],
        "operator": record.get("operator") or "",
        "date": str(record.get("ended_at") or "")[:10],
        "plain": plain,
    }


def _env():
    import jinja2

    # autoescape=True: select_autoescape() goes by extension and `.html.j2` is not `.html`
    return jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES), autoescape=True,
                              trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined)


def render_html(record: dict[str, Any], compensation: Compensation | None = None) -> str:
    """The certificate as one self-contained HTML page (A4 when printed)."""
    return _env().get_template("certificate.html.j2").render(standalone=True, **context(record, compensation))


def certificate_section(record: dict[str, Any], compensation: Compensation | None = None) -> str:
    """The certificate's body (one <section>, a page of its own before what follows when printed),
    for the run report's `certificate` block (bench.reporting.unit_certificate)."""
    return _env().get_template("certificate.html.j2").render(standalone=False, **context(record, compensation))


def write_certificate(record: dict[str, Any], path: str | Path, *, pdf: bool = False,
                      compensation: Compensation | None = None) -> list[Path]:
    """Write the HTML certificate to path and, with pdf, the PDF beside it (same name, .pdf)."""
    from bench.pdf import write_pdf

    path = Path(path)
    html = render_html(record, compensation)
    path.write_text(html)
    out = [path]
    if pdf:
        out.append(write_pdf(html, path.with_suffix(".pdf")))
    return out


def pdf_available() -> bool:
    """Whether WeasyPrint can write the certificate's PDF here."""
    try:
        from bench.pdf import require_weasyprint

        require_weasyprint()
    except Exception:  # noqa: BLE001 - any failure to load it means no PDF
        return False
    return True


def write_unit_documents(record: dict[str, Any], directory: str | Path, *, pdf: bool = False) -> dict[str, Path]:
    """A unit's certificate (HTML, and PDF with pdf) and, when it has trim coefficients, its
    compensation file, named SERIAL-aATTEMPT.certificate.html / .compensation.toml in directory."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    stem = f"{record.get('serial', 'unit')}-a{record.get('attempt', 1)}"
    try:
        comp = from_record(record)
    except CompensationError:
        comp = None
    out: dict[str, Path] = {}
    paths = write_certificate(record, directory / f"{stem}.certificate.html", pdf=pdf, compensation=comp)
    out["certificate"] = paths[0]
    if pdf:
        out["certificate_pdf"] = paths[1]
    if comp is not None:
        path = directory / f"{stem}.compensation.toml"
        loaded = (record.get("trims") or {}).get("file")
        if loaded and Path(loaded) == path and path.exists():  # the file loaded into the NVM: kept as it was hashed
            out["compensation"] = path
        else:
            out["compensation"] = comp.write(path)
    return out
