"""The server-rendered pages' Jinja2 templates (``templates/``, no front-end build step) and their filters."""

from __future__ import annotations

import math
from pathlib import Path
from urllib.parse import quote

from fastapi.templating import Jinja2Templates

from station.kernel.display import display_of_check, format_number, format_value, limits_identity, local_time
from station.web.labels import parameter_label, unit_label

TEMPLATES_DIR = Path(__file__).resolve().parent / "templates"


def fmt(value: float | None) -> str:
    """A number for a table cell: 4 significant digits, '—' for a missing or non-finite value."""
    if value is None or not math.isfinite(value):
        return "—"
    return f"{value:.4g}"


def path_part(value: object) -> str:
    """A value as one URL path segment: every reserved character encoded, "/" too (a serial may hold any
    printable character; the routes take it back with a path converter)."""
    return quote(str(value), safe="")


templates = Jinja2Templates(directory=str(TEMPLATES_DIR))
templates.env.filters["path_part"] = path_part
templates.env.filters["fmt"] = fmt
templates.env.filters["label"] = parameter_label
templates.env.filters["unit"] = unit_label
templates.env.filters["localtime"] = local_time
templates.env.globals["display_of"] = display_of_check
templates.env.globals["format_value"] = format_value
templates.env.globals["format_number"] = format_number
templates.env.globals["limits_identity"] = limits_identity

__all__ = ["TEMPLATES_DIR", "fmt", "path_part", "templates"]
