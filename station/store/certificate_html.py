"""The calibration certificate as an HTML document (``templates/certificate.html``, Jinja2 with autoescape).

The page ``GET /units/{serial}/certificate.html`` and ``station units certificate -o FILE.html`` render
the same document from :class:`~station.store.certificate.Certificate`.
"""

from __future__ import annotations

from pathlib import Path

from jinja2 import Environment, FileSystemLoader, select_autoescape

from station.kernel.display import local_time
from station.store.certificate import COVERAGE_K, Certificate

__all__ = ["UNITS_NOTE", "certificate_html"]

#: The display convention in one sentence (both renderings state it).
UNITS_NOTE = ("accelerometer quantities in mg (1 mg = 9.80665e-3 m/s²), gyroscope quantities in deg/s, "
              "scale-factor errors (M_ii − 1) and cross-axis terms (M_ij) in ppm, times in s, temperature "
              "coefficients per K")

_ENV = Environment(loader=FileSystemLoader(str(Path(__file__).resolve().parent / "templates")),
                   autoescape=select_autoescape(["html"]))


def certificate_html(cert: Certificate) -> str:
    """The certificate as one self-contained HTML page (no external resources)."""
    return _ENV.get_template("certificate.html").render(c=cert, k=f"{COVERAGE_K:g}", t=local_time,
                                                         units_note=UNITS_NOTE)
