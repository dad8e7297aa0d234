"""pattern.svg of a DXF pattern imported in one size: its panels as the garment uses them (cut on
the fold: unfolded; turned grain up), laid out in rows; each seam in its own colour, numbered on
both its sides, with a legend (what it sews, from which corner to which); corners numbered as
the assembly file counts them (c0, c1 ...), notches, grain lines; the pieces left out and what
the inference is unsure of, in words. The sheet scales to the window (viewBox in cm)."""

from __future__ import annotations

from html import escape

import numpy as np

from engine.pattern.dxf_infer import Part, Seam, span_points

COLOURS = ["#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#e377c2", "#8c564b", "#bcbd22",
           "#7f7f7f", "#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173"]
MARGIN = 4.0  # cm between panels
LINE = 2.6  # cm: legend line height


def _layout(parts: list[Part]) -> tuple[dict[str, np.ndarray], float, float]:
    """Each part's offset (its outline + offset lies in the sheet, y up) in rows no wider than
    about 1.6 x the square root of the panels' area (at least the widest)."""
    sizes = {p.name: np.ptp(p.outline, axis=0) for p in parts}
    area = sum(float(w * h) for w, h in sizes.values())
    row_w = max(1.6 * np.sqrt(area), max(w for w, _ in sizes.values()))
    offsets, x, y_top, row_h, width = {}, MARGIN, 0.0, 0.0, 0.0
    for p in parts:
        w, h = sizes[p.name]
        if x > MARGIN and x + w > row_w + MARGIN:
            y_top -= row_h + MARGIN
            x, row_h = MARGIN, 0.0
        lo, hi = p.outline.min(axis=0), p.outline.max(axis=0)
        offsets[p.name] = np.array([x - lo[0], y_top - MARGIN - hi[1]])
        x += w + MARGIN
        row_h = max(row_h, h)
        width = max(width, x)
    return offsets, width, -(y_top - row_h - MARGIN)


def imported_svg(parts: list[Part], seams: list[Seam], title: str, notes: list[str]) -> str:
    offsets, width, height = _layout(parts)
    legend = [title] + [f"{k + 1}  {s.label}" for k, s in enumerate(seams)] + notes
    total_h = height + LINE * (len(legend) + 2)

    def xy(p):  # sheet cm (y up) -> svg (y down)
        return p[..., 0], -p[..., 1]

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="100%" viewBox="0 0 {width:.2f} {total_h:.2f}">',
           '<style>text{font-family:sans-serif}</style>',
           f'<rect width="{width:.2f}" height="{total_h:.2f}" fill="#fff"/>']
    by = {p.name: p for p in parts}
    for p in parts:
        out += _panel(p, offsets[p.name], xy)
    for k, s in enumerate(seams):
        c = COLOURS[k % len(COLOURS)]
        for sp in (s.a, s.b):
            pts = span_points(by[sp.part].outline, sp) + offsets[sp.part]
            x, y = xy(pts)
            d = " ".join(f"{a:.2f},{b:.2f}" for a, b in zip(x, y))
            out.append(f'<polyline points="{d}" fill="none" stroke="{c}" stroke-width="0.7" stroke-opacity="0.85"/>')
            m = len(x) // 2
            out.append(f'<text x="{x[m]:.2f}" y="{y[m]:.2f}" font-size="2.6" font-weight="bold" fill="{c}" '
                       f'stroke="#fff" stroke-width="0.15">{k + 1}</text>')
    y0 = height + 2 * LINE
    for i, line in enumerate(legend):
        c = COLOURS[(i - 1) % len(COLOURS)] if 1 <= i <= len(seams) else "#222"
        out.append(f'<text x="{MARGIN:.2f}" y="{y0 + i * LINE:.2f}" font-size="1.9" fill="{c}">{escape(line)}</text>')
    out.append("</svg>")
    return "\n".join(out)


def _panel(p: Part, off: np.ndarray, xy) -> list[str]:
    o = p.outline + off
    x, y = xy(o)
    pts = " ".join(f"{a:.2f},{b:.2f}" for a, b in zip(x, y))
    out = [f'<polygon points="{pts}" fill="#f3e7d3" stroke="#333" stroke-width="0.15"/>']
    for i, c in enumerate(p.corners):
        cx, cy = xy(o[c])
        out.append(f'<circle cx="{cx:.2f}" cy="{cy:.2f}" r="0.35" fill="#555"/>')
        out.append(f'<text x="{cx + 0.5:.2f}" y="{cy - 0.5:.2f}" font-size="1.5" fill="#777">c{i}</text>')
    for q in p.notches + off if len(p.notches) else []:
        nx, ny = xy(q)
        out.append(f'<path d="M{nx - 0.6:.2f},{ny - 0.9:.2f} L{nx + 0.6:.2f},{ny - 0.9:.2f} L{nx:.2f},{ny:.2f} Z" '
                   'fill="#444"/>')
    if p.grain is not None:
        (ax, ay), (bx, by) = (xy(g) for g in p.grain + off)
        out.append(f'<line x1="{ax:.2f}" y1="{ay:.2f}" x2="{bx:.2f}" y2="{by:.2f}" stroke="#666" '
                   'stroke-width="0.2" stroke-dasharray="1,0.6"/>')
    cx, cy = xy(np.array([0.5 * (o[:, 0].min() + o[:, 0].max()), o[:, 1].mean()]))
    side = f" ({p.side})" if p.side else ""
    out.append(f'<text x="{cx:.2f}" y="{cy:.2f}" font-size="2.4" text-anchor="middle">{escape(p.name)}</text>')
    out.append(f'<text x="{cx:.2f}" y="{cy + 2.6:.2f}" font-size="1.6" text-anchor="middle" fill="#666">'
               f'{escape(p.piece)}: {escape(p.role)}{side}{", unfolded" if p.unfolded else ""}</text>')
    return out
