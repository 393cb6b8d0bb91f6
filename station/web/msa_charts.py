"""The Gage R&R study's charts (server-rendered SVG, as the quality page's): components of variation, the range
chart per part and appraiser, and each part's measurements by appraiser. Values in the display unit."""

from __future__ import annotations

from html import escape

from station.kernel.display import Display
from station.msa.study import ParameterStudy
from station.web.charts import FONT, MB, ML, MR, MT, H, W
from station.web.charts import fmt_tick as _fmt
from station.web.charts import frame as _frame
from station.web.charts import scale as _scale
from station.web.charts import yticks as _yticks

# control chart constant D4 of the range chart (AIAG SPC manual, appendix) for subgroups of 2 .. 10
D4 = {2: 3.267, 3: 2.574, 4: 2.282, 5: 2.114, 6: 2.004, 7: 1.924, 8: 1.864, 9: 1.816, 10: 1.777}
COLOURS = ("#1565c0", "#2e7d32", "#ef6c00", "#6a1b9a", "#00838f", "#c62828", "#4e342e", "#37474f")


def components_svg(p: ParameterStudy) -> str:
    """Bars per component: % of the total variation (blue), % contribution (green), % of the tolerance (grey)."""
    g = p.study
    title = f"{p.parameter}: components of variation (%)"
    if g is None:
        return "".join([*_frame(title), f'<text x="{ML}" y="100" {FONT} font-size="12">not analysed</text></svg>'])
    comps = [("EV", g.repeatability), ("AV", g.reproducibility), ("INT", g.interaction), ("GRR", g.grr),
             ("PV", g.part)]
    series = [("%TV", "#1565c0", [c.pct_total for _, c in comps]),
              ("%contribution", "#2e7d32", [c.pct_contribution for _, c in comps])]
    if g.tolerance is not None:
        series.append(("%tolerance", "#9e9e9e", [c.pct_tolerance or 0.0 for _, c in comps]))
    top = max([100.0] + [v for _, _, vs in series for v in vs if v == v])
    _, _, y = _scale(0.0, top * 1.05, H - MB, MT)
    out = _frame(title) + _yticks(0.0, top * 1.05, y)
    group = (W - ML - MR) / len(comps)
    bar = group * 0.8 / len(series)
    for i, (name, _) in enumerate(comps):
        for k, (label, colour, values) in enumerate(series):
            v = values[i] if values[i] == values[i] else 0.0
            x0 = ML + i * group + group * 0.1 + k * bar
            out.append(f'<rect x="{x0:.1f}" y="{y(v):.1f}" width="{bar - 1:.1f}" height="{y(0) - y(v):.1f}" '
                       f'fill="{colour}"><title>{escape(f"{name} {label}: {v:.1f}")}</title></rect>')
        out.append(f'<text x="{ML + (i + 0.5) * group:.1f}" y="{H - MB + 14}" {FONT} font-size="10" '
                   f'text-anchor="middle">{name}</text>')
    legend = "; ".join(f"{label} {'blue' if c == '#1565c0' else 'green' if c == '#2e7d32' else 'grey'}"
                       for label, c, _ in series)
    out.append(f'<text x="{ML}" y="{H - 6}" {FONT} font-size="10" fill="#444">{escape(legend)}</text></svg>')
    return "".join(out)


def range_chart_svg(p: ParameterStudy, d: Display) -> str:
    """Range of the repeats of each part in each appraiser, grouped by appraiser; R-bar and UCL = D4 R-bar."""
    title = f"{p.parameter}: range chart ({d.unit})"
    cells = p.cells
    if not cells or len(cells[0][2]) < 2:
        return "".join([*_frame(title), f'<text x="{ML}" y="100" {FONT} font-size="12">no repeats</text></svg>'])
    apps = sorted({a for _, a, _ in cells})
    ordered = [c for a in apps for c in cells if c[1] == a]
    ranges = [float(d.spread(max(v) - min(v)) or 0.0) for _, _, v in ordered]
    rbar = sum(ranges) / len(ranges)
    ucl = D4.get(len(cells[0][2]), 3.267) * rbar
    lo, hi, y = _scale(0.0, max([*ranges, ucl]) * 1.05, H - MB, MT)
    out = _frame(title) + _yticks(lo, hi, y)
    n = len(ordered)

    def x(i: int) -> float:
        return ML + (i + 0.5) * (W - ML - MR) / n

    for value, colour, dash in ((rbar, "#2e7d32", ""), (ucl, "#c62828", ' stroke-dasharray="4 3"')):
        out.append(f'<line x1="{ML}" x2="{W - MR}" y1="{y(value):.1f}" y2="{y(value):.1f}" stroke="{colour}"{dash}/>')
    for i, ((part, app, _), r) in enumerate(zip(ordered, ranges, strict=True)):
        colour = COLOURS[apps.index(app) % len(COLOURS)]
        big = r > ucl
        out.append(f'<circle cx="{x(i):.1f}" cy="{y(r):.1f}" r="{3.2 if big else 2.4}" '
                   f'fill="{"#c62828" if big else colour}"><title>{escape(f"{part} in {app}: R {_fmt(r)}")}'
                   '</title></circle>')
    for k, app in enumerate(apps):
        first = next(i for i, c in enumerate(ordered) if c[1] == app)
        out.append(f'<text x="{x(first):.1f}" y="{H - MB + 14}" {FONT} font-size="10" '
                   f'fill="{COLOURS[k % len(COLOURS)]}">{escape(app)}</text>')
    out.append(f'<text x="{ML}" y="{H - 6}" {FONT} font-size="10" fill="#444">R-bar {_fmt(rbar)} (green), '
               f'UCL {_fmt(ucl)} (red dashed); a range above it in red</text></svg>')
    return "".join(out)


def parts_by_appraiser_svg(p: ParameterStudy, d: Display) -> str:
    """Each part's measurements (x: part), one colour per appraiser, the appraiser's mean per part joined."""
    title = f"{p.parameter}: parts by {'appraiser'} ({d.unit})"
    cells = p.cells
    if not cells:
        return "".join([*_frame(title), f'<text x="{ML}" y="100" {FONT} font-size="12">no data</text></svg>'])
    parts = sorted({c[0] for c in cells})
    apps = sorted({c[1] for c in cells})
    vals = [float(d.convert(v)) for _, _, vs in cells for v in vs]
    lo, hi, y = _scale(min(vals), max(vals), H - MB, MT)
    out = _frame(title) + _yticks(lo, hi, y)
    n = len(parts)

    def x(i: int, k: int) -> float:
        return ML + (i + 0.5) * (W - ML - MR) / n + (k - (len(apps) - 1) / 2) * 4.0

    for k, app in enumerate(apps):
        colour = COLOURS[k % len(COLOURS)]
        means = []
        for i, part in enumerate(parts):
            values = next((vs for pp, aa, vs in cells if pp == part and aa == app), ())
            for v in values:
                out.append(f'<circle cx="{x(i, k):.1f}" cy="{y(d.convert(v)):.1f}" r="2" fill="{colour}" '
                           f'fill-opacity="0.6"><title>{escape(f"{part} in {app}: {_fmt(d.convert(v))}")}</title>'
                           '</circle>')
            if values:
                means.append(f"{x(i, k):.1f},{y(d.convert(sum(values) / len(values))):.1f}")
        out.append(f'<polyline points="{" ".join(means)}" fill="none" stroke="{colour}" stroke-width="1.2"/>')
    legend = ", ".join(f"{a}" for a in apps)
    out.append(f'<text x="{ML}" y="{H - 6}" {FONT} font-size="10" fill="#444">parts 1-{n} left to right; '
               f'{escape(legend)} in their colours</text></svg>')
    return "".join(out)


__all__ = ["D4", "components_svg", "parts_by_appraiser_svg", "range_chart_svg"]
