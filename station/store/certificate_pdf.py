"""The calibration certificate as a PDF (reportlab's platypus: paragraphs and tables on A4 pages).

reportlab is the established pure-Python PDF library (no external renderer); the document states what
:class:`~station.store.certificate.Certificate` holds, in the display convention of
:mod:`station.kernel.display`, with the same sections as the HTML rendering. Fonts: reportlab's
built-in Helvetica, whose WinAnsi encoding has "±", "°" and "µ" (so text extraction finds them).
"""

from __future__ import annotations

import io
from typing import Any
from xml.sax.saxutils import escape

from station.kernel.display import local_time
from station.store.certificate import COVERAGE_K, Certificate, CertificateResult
from station.store.certificate_html import UNITS_NOTE

__all__ = ["certificate_pdf"]


def _p(text: str, style: Any) -> Any:
    from reportlab.platypus import Paragraph

    return Paragraph(escape(text), style)


def _ascii(text: str) -> str:
    """Characters Helvetica (WinAnsi) has no glyph for, spelled out."""
    return (text.replace("←", "<-").replace("σ", "sigma").replace("−", "-").replace("²", "^2")
            .replace("·", "*"))


def certificate_pdf(cert: Certificate) -> bytes:
    """The certificate as PDF bytes (A4, one or more pages)."""
    from reportlab.lib import colors
    from reportlab.lib.pagesizes import A4
    from reportlab.lib.styles import getSampleStyleSheet
    from reportlab.lib.units import mm
    from reportlab.platypus import SimpleDocTemplate, Spacer, Table, TableStyle

    styles = getSampleStyleSheet()
    body, small, h1, h2 = styles["BodyText"], styles["BodyText"].clone("small", fontSize=7.5, leading=9), \
        styles["Title"], styles["Heading2"]
    cell = styles["BodyText"].clone("cell", fontSize=7.5, leading=9)
    mono = styles["BodyText"].clone("mono", fontName="Courier", fontSize=7, leading=8.5)
    k = f"{COVERAGE_K:g}"
    story: list[Any] = [
        _p("Calibration certificate", h1),
        _p(f"IMU unit {cert.serial} - run {cert.run_id} - verdict {cert.verdict}", styles["Heading2"]),
    ]
    if cert.verdict_reason:
        story.append(_p(_ascii(cert.verdict_reason), body))

    def facts_table(rows: list[tuple[str, str]]) -> Any:
        t = Table([[_p(a, cell), _p(_ascii(b), mono if "sha256" in b else cell)] for a, b in rows],
                  colWidths=[40 * mm, 130 * mm])
        t.setStyle(TableStyle([("VALIGN", (0, 0), (-1, -1), "TOP"), ("BOTTOMPADDING", (0, 0), (-1, -1), 1),
                               ("TOPPADDING", (0, 0), (-1, -1), 1)]))
        return t

    date = local_time(cert.started_at) + (f" to {local_time(cert.finished_at)}" if cert.finished_at else "")
    facts = [
        ("date", date),
        ("station", f"{cert.station} (slot {cert.slot}, host {cert.host or '-'})"),
        ("rig (reference equipment)", cert.rig or "-"),
        ("sensor port", cert.sensor_url or "-"),
        ("operator", cert.operator or "-"),
        ("lot", cert.lot or "-"),
        ("software", cert.software_version or "-"),
        ("sequence", f"{cert.sequence_version or '-'}, sha256 {cert.sequence_hash or '-'}"),
        ("limits file", f"{cert.limits_version or '-'}, sha256 {cert.limits_hash or '-'}"),
        ("sample period", f"{cert.sample_period_s * 1000:.4g} ms"),
        ("parameter set", f"{cert.params_format}, sha256 {cert.params_sha256}"),
    ]
    if cert.gravity_mps2:
        facts.insert(-2, ("local gravity", f"{cert.gravity_mps2:.5f} m/s^2"))
    if cert.reference_temperature_degc == cert.reference_temperature_degc:
        facts.insert(-1, ("reference temperature", f"{cert.reference_temperature_degc:.2f} degC"))
    if cert.eeprom_image_sha256:
        facts.append(("EEPROM image", f"sha256 {cert.eeprom_image_sha256}, read back "
                                      f"{'and verified' if cert.eeprom_verified else 'NOT verified'}"))
    if cert.disposition:
        facts.append(("disposition", cert.disposition))
    story += [_p("Calibration", h2), facts_table(facts), _p("Decision rule", h2), _p(_ascii(cert.decision_rule), body),
              _p("Parameters", h2),
              _p(_ascii(f"Value ± U, U the expanded uncertainty with coverage factor k = {k} (about 95 %). Units: "
                        f"{UNITS_NOTE}. '-': not determined by the recording."), small),
              Spacer(1, 2 * mm)]
    shade = {"FAIL": colors.HexColor("#fde4e4"), "INCONCLUSIVE": colors.HexColor("#fde4e4"),
             "MARGINAL": colors.HexColor("#fff4c2")}
    rows = [[_p(h, cell) for h in ("sensor", "parameter", f"value ± U (k = {k})", "limits", "verdict")]]
    style = [("GRID", (0, 0), (-1, -1), 0.25, colors.grey), ("BACKGROUND", (0, 0), (-1, 0), colors.HexColor("#e8eaed")),
             ("VALIGN", (0, 0), (-1, -1), "TOP")]
    for i, p in enumerate(cert.parameters, start=1):
        rows.append([_p(p.group, cell), _p(_ascii(p.label), cell), _p(_ascii(p.shown()), cell),
                     _p(_ascii(p.shown_limits()), cell), _p(p.verdict or "-", cell)])
        if p.verdict in shade:
            style.append(("BACKGROUND", (0, i), (-1, i), shade[p.verdict]))
    table = Table(rows, colWidths=[24 * mm, 52 * mm, 42 * mm, 38 * mm, 22 * mm], repeatRows=1)
    table.setStyle(TableStyle(style))
    story.append(table)

    def results(title: str, items: tuple[CertificateResult, ...], empty: str) -> None:
        story.append(_p(title, h2))
        if not items:
            story.append(_p(empty, body))
            return
        data = [[_p(h, cell) for h in ("check", "value", "limits", "result")]]
        data += [[_p(r.name, cell), _p(_ascii(r.shown()), cell), _p(_ascii(r.shown_limits()), cell),
                  _p(r.verdict, cell)] for r in items]
        t = Table(data, colWidths=[62 * mm, 38 * mm, 50 * mm, 28 * mm], repeatRows=1)
        t.setStyle(TableStyle([("GRID", (0, 0), (-1, -1), 0.25, colors.grey),
                               ("BACKGROUND", (0, 0), (-1, 0), colors.HexColor("#e8eaed"))]))
        story.append(t)

    results("Verification on the rig (corrected output)", cert.verification,
            "No verification on the rig was recorded for this run.")
    story.append(_p(f"{cert.checks_total} recorded checks in this run (capture gates, product limits, fit quality, "
                    f"verification), {cert.checks_failed} failed.", body))
    results("Fit quality", cert.fit_quality, "No fit-quality checks were recorded.")
    story += [_p("Checking this document", h2),
              _p(f"The parameter set's SHA-256 above is the hash of the stored parameter set (parameter_sets.sha256, "
                 f"the SHA-256 of its JSON text as the run wrote it); 'station units certificate {cert.serial} --run "
                 f"{cert.run_id}' recomputes it from the database and refuses to issue a certificate when the record "
                 f"does not match. Issued {local_time(cert.issued_at)}.", body)]

    buf = io.BytesIO()

    def footer(canvas: Any, doc: Any) -> None:
        canvas.saveState()
        canvas.setFont("Helvetica", 7)
        canvas.drawString(18 * mm, 10 * mm, f"Calibration certificate {cert.serial}, run {cert.run_id} - "
                                            f"page {doc.page}")
        canvas.restoreState()

    doc = SimpleDocTemplate(buf, pagesize=A4, leftMargin=18 * mm, rightMargin=18 * mm, topMargin=15 * mm,
                            bottomMargin=18 * mm, title=f"Calibration certificate {cert.serial}",
                            author=cert.station, subject=f"run {cert.run_id}", invariant=True)
    doc.build(story, onFirstPage=footer, onLaterPages=footer)
    return buf.getvalue()
