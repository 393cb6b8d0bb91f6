"""Small server-rendered SVG charts for the quality page (plain strings; no plotting library, a few ms each):
an X-bar control chart with its limits and the points that complete a run rule, a histogram with the limits
and the fitted normal, a yield trend, and the golden unit's individuals chart (each check's deviation from the
reference, ± 3 sigma of the registered repeatability dashed red, the check's allowed deviation dotted grey, the
points completing a Nelson rule red; in the display convention, a deviation being a spread). Values are drawn in
the parameter's unit."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from html import escape

from station.kernel.display import display_of_check
from station.kernel.golden import GoldenReference, GoldenTrend
from station.store.quality import Histogram, ParameterChart

W, H = 460, 200
ML, MR, MT, MB = 64, 12, 24, 34
FONT = 'font-family="system-ui,sans-serif"'


def _fmt(x: float) -> str:
    if x == 0 or not math.isfinite(x):
        return "0" if x == 0 else "-"
    return f"{x:.4g}"


def _scale(lo: float, hi: float, a: float, b: float) -> tuple[float, float, Callable[[float], float]]:
    if not hi > lo:
        pad = abs(lo) * 0.01 or 1e-9
        lo, hi = lo - pad, hi + pad
    return lo, hi, (lambda v: a + (v - lo) / (hi - lo) * (b - a))


def _frame(title: str, width: int = W, height: int = H) -> list[str]:
    return [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" width="100%" '
            f'style="width:100%;height:auto" role="img" aria-label="{escape(title)}">',
            f'<rect width="{width}" height="{height}" fill="#fff"/>',
            f'<text x="{ML}" y="15" {FONT} font-size="12" font-weight="600">{escape(title)}</text>']


def _yticks(lo: float, hi: float, y: Callable[[float], float], width: int = W) -> list[str]:
    out = []
    for k in range(5):
        v = lo + (hi - lo) * k / 4
        out.append(f'<line x1="{ML}" x2="{width - MR}" y1="{y(v):.1f}" y2="{y(v):.1f}" stroke="#eee"/>'
                   f'<text x="{ML - 4}" y="{y(v) + 4:.1f}" {FONT} font-size="10" text-anchor="end">{_fmt(v)}</text>')
    return out


def _slots(n: int) -> Callable[[int], float]:
    """The x of point ``i`` of ``n`` equally spaced points."""
    return lambda i: ML + (i + 0.5) * (W - ML - MR) / n


def _centre_line(y_px: float) -> str:
    return (f'<line x1="{ML}" x2="{W - MR}" y1="{y_px:.1f}" y2="{y_px:.1f}" stroke="#2e7d32" '
            'stroke-width="1.5"/>')


def _x_labels(labels: Sequence[str], x: Callable[[int], float]) -> list[str]:
    """The first, middle and last point's label under the axis."""
    n = len(labels)
    out = []
    for i in sorted({0, n // 2, n - 1}):
        anchor = "start" if i == 0 and n > 1 else "end" if i == n - 1 and n > 1 else "middle"
        out.append(f'<text x="{x(i):.1f}" y="{H - MB + 14}" {FONT} font-size="10" text-anchor="{anchor}">'
                   f'{escape(labels[i])}</text>')
    return out


def control_chart_svg(pc: ParameterChart) -> str:
    """X-bar chart per day: points, centre line, per-day control limits, points completing a run rule in red."""
    ch = pc.chart
    pts = ch.points
    title = f"{pc.name} ({pc.unit}) daily mean"
    if not pts:
        return "".join([*_frame(title), f'<text x="{ML}" y="100" {FONT} font-size="12">no data</text></svg>'])
    vals = [p.mean for p in pts] + [p.lcl for p in pts if p.lcl is not None] + \
        [p.ucl for p in pts if p.ucl is not None] + [ch.center]
    lo, hi, y = _scale(min(vals), max(vals), H - MB, MT)
    n = len(pts)
    x = _slots(n)
    out = [*_frame(title), *_yticks(lo, hi, y), _centre_line(y(ch.center))]
    for attr in ("ucl", "lcl"):
        seg = " ".join(f"{x(i):.1f},{y(getattr(p, attr)):.1f}" for i, p in enumerate(pts)
                       if getattr(p, attr) is not None)
        if seg:
            out.append(f'<polyline points="{seg}" fill="none" stroke="#c62828" stroke-dasharray="4 3"/>')
    out.append('<polyline points="' + " ".join(f"{x(i):.1f},{y(p.mean):.1f}" for i, p in enumerate(pts))
               + '" fill="none" stroke="#1565c0" stroke-width="1.2"/>')
    for i, p in enumerate(pts):
        bad = bool(p.rules)
        tip = f"{p.label}: mean {_fmt(p.mean)} n={p.n}" + (f" rules {','.join(map(str, p.rules))}" if bad else "")
        out.append(f'<circle cx="{x(i):.1f}" cy="{y(p.mean):.1f}" r="{3.2 if bad else 2.2}" '
                   f'fill="{"#c62828" if bad else "#1565c0"}"><title>{escape(tip)}</title></circle>')
    out += _x_labels([p.label for p in pts], x)
    legend = "UCL/LCL dashed, centre green" + (f"; rules violated: {', '.join(map(str, ch.violations))}"
                                              if ch.violations else "; no rule violated")
    out.append(f'<text x="{ML}" y="{H - 6}" {FONT} font-size="10" fill="#444">{escape(legend)}</text></svg>')
    return "".join(out)


def histogram_svg(h: Histogram) -> str:
    """Bars of the counts, the limits as red lines, the normal of the same n, mean and sigma as a curve."""
    title = f"{h.name} ({h.unit}) n={h.n}"
    _lo, _hi, x = _scale(h.lo, h.hi, ML, W - MR)
    nb = len(h.counts)
    width = (h.hi - h.lo) / nb
    peak = max(h.counts) if h.counts else 1
    normal = []
    if h.sigma and h.sigma > 0:
        for k in range(121):
            v = h.lo + (h.hi - h.lo) * k / 120
            normal.append((v, h.n * width / (h.sigma * math.sqrt(2 * math.pi))
                           * math.exp(-0.5 * ((v - h.mean) / h.sigma) ** 2)))
    top = max([peak] + [c for _, c in normal]) or 1
    _, _, y = _scale(0, top * 1.08, H - MB, MT)
    out = _frame(title)
    for k in range(5):
        c = top * 1.08 * k / 4
        out.append(f'<line x1="{ML}" x2="{W - MR}" y1="{y(c):.1f}" y2="{y(c):.1f}" stroke="#eee"/>'
                   f'<text x="{ML - 4}" y="{y(c) + 4:.1f}" {FONT} font-size="10" text-anchor="end">{round(c)}</text>')
    for k, c in enumerate(h.counts):
        if c:
            x0, x1 = x(h.lo + k * width), x(h.lo + (k + 1) * width)
            out.append(f'<rect x="{x0:.1f}" y="{y(c):.1f}" width="{max(x1 - x0 - 0.5, 0.5):.1f}" '
                       f'height="{y(0) - y(c):.1f}" fill="#90caf9"><title>{c}</title></rect>')
    if normal:
        out.append('<polyline points="' + " ".join(f"{x(v):.1f},{y(c):.1f}" for v, c in normal)
                   + '" fill="none" stroke="#0d47a1" stroke-width="1.4"/>')
    for lim, name in ((h.low, "LSL"), (h.high, "USL")):
        if lim is not None:
            out.append(f'<line x1="{x(lim):.1f}" x2="{x(lim):.1f}" y1="{MT}" y2="{H - MB}" stroke="#c62828" '
                       f'stroke-width="1.6"/><text x="{x(lim):.1f}" y="{MT + 10}" {FONT} font-size="10" '
                       f'fill="#c62828" text-anchor="middle">{name}</text>')
    for v, anchor in ((h.lo, "start"), ((h.lo + h.hi) / 2, "middle"), (h.hi, "end")):
        out.append(f'<text x="{x(v):.1f}" y="{H - MB + 14}" {FONT} font-size="10" text-anchor="{anchor}">'
                   f'{_fmt(v)}</text>')
    sig = f", sigma {_fmt(h.sigma)}" if h.sigma else ""
    out.append(f'<text x="{ML}" y="{H - 6}" {FONT} font-size="10" fill="#444">normal fit: mean {_fmt(h.mean)}{sig}'
               '</text></svg>')
    return "".join(out)


def yield_trend_svg(labels: Sequence[str], fpy: Sequence[float | None], final: Sequence[float | None]) -> str:
    """First-pass (blue) and final (green) yield per day, %."""
    w = 1400
    title = "yield per day (%): first pass blue, final green"
    vals = [v for v in list(fpy) + list(final) if v is not None]
    out = _frame(title, w)
    if not vals:
        return "".join([*out, f'<text x="{ML}" y="100" {FONT} font-size="12">no tested units</text></svg>'])
    lo = float(min(math.floor(min(vals) * 100 - 0.5), 96))
    lo -= (100 - lo) % 4  # four equal steps of whole percent up to 100
    _, _, y = _scale(lo, 100.0, H - MB, MT)
    out += _yticks(lo, 100.0, y, w)
    n = len(labels)

    def x(i: int) -> float:
        return ML + (i + 0.5) * (w - ML - MR) / max(n, 1)

    for series, colour in ((fpy, "#1565c0"), (final, "#2e7d32")):
        seg = " ".join(f"{x(i):.1f},{y(v * 100):.1f}" for i, v in enumerate(series) if v is not None)
        out.append(f'<polyline points="{seg}" fill="none" stroke="{colour}" stroke-width="1.6"/>')
    for i in sorted({0, n // 2, n - 1}):
        anchor = "start" if i == 0 else "end" if i == n - 1 else "middle"
        out.append(f'<text x="{x(i):.1f}" y="{H - MB + 14}" {FONT} font-size="10" text-anchor="{anchor}">'
                   f'{escape(labels[i])}</text>')
    out.append("</svg>")
    return "".join(out)


def golden_chart_svg(trend: GoldenTrend, ref: GoldenReference, labels: list[str]) -> str:
    """The individuals chart of ``trend`` (one point per check, ``labels`` its dates)."""
    d = display_of_check(trend.parameter, trend.unit)
    sigma = d.spread(ref.repeatability) or 0.0
    allowed = d.spread(ref.allowed) or 0.0
    dev = [d.spread(v) if v is not None else None for v in trend.deviations]
    title = f"{trend.parameter} ({d.unit}) golden deviation"
    shown = [v for v in dev if v is not None]
    if not shown:
        return "".join([*_frame(title), f'<text x="{ML}" y="100" {FONT} font-size="12">no check</text></svg>'])
    lo, hi, y = _scale(min([*shown, -3 * sigma, -allowed]), max([*shown, 3 * sigma, allowed]), H - MB, MT)
    n = len(dev)
    x = _slots(n)
    out = [*_frame(title), *_yticks(lo, hi, y), _centre_line(y(0.0))]
    limit, band = 'stroke="#c62828" stroke-dasharray="4 3"', 'stroke="#888" stroke-dasharray="1 3"'
    for level, style in ((3 * sigma, limit), (-3 * sigma, limit), (allowed, band), (-allowed, band)):
        out.append(f'<line x1="{ML}" x2="{W - MR}" y1="{y(level):.1f}" y2="{y(level):.1f}" {style}/>')
    seg = " ".join(f"{x(i):.1f},{y(v):.1f}" for i, v in enumerate(dev) if v is not None)
    out.append(f'<polyline points="{seg}" fill="none" stroke="#1565c0" stroke-width="1.2"/>')
    for i, point in enumerate(dev):
        if point is None:
            continue
        rules = trend.rules[i]
        tip = f"check {i + 1} ({labels[i]}): {_fmt(point)} {d.unit}" + (f" rules {','.join(map(str, rules))}"
                                                                     if rules else "")
        out.append(f'<circle class="{"signal" if rules else "point"}" cx="{x(i):.1f}" cy="{y(point):.1f}" '
                   f'r="{3.2 if rules else 2.2}" fill="{"#c62828" if rules else "#1565c0"}">'
                   f'<title>{escape(tip)}</title></circle>')
    out += _x_labels(labels, x)
    first = trend.first_signal
    legend = ("±3σ dashed, allowed dotted; " + (f"first signal at check {first + 1}" if first is not None
                                                 else "in control"))
    out.append(f'<text x="{ML}" y="{H - 6}" {FONT} font-size="10" fill="#444">{escape(legend)}</text></svg>')
    return "".join(out)


#: the drawing helpers the other chart modules (e.g. :mod:`station.web.msa_charts`) share
fmt_tick, frame, scale, yticks = _fmt, _frame, _scale, _yticks

__all__ = [
    "FONT",
    "MB",
    "ML",
    "MR",
    "MT",
    "H",
    "W",
    "control_chart_svg",
    "fmt_tick",
    "frame",
    "golden_chart_svg",
    "histogram_svg",
    "scale",
    "yield_trend_svg",
    "yticks",
]

