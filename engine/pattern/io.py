"""Read and write pattern files: GarmentCode JSON specs (round trip) and SVG drawings."""

from __future__ import annotations

import json
from html import escape
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from engine.errors import InputError, parser
from engine.pattern import geometry as geo
from engine.pattern.spec import PatternSpec

MAX_PATTERN_BYTES = 20_000_000


@parser("a GarmentCode pattern", name_of=lambda data, source="pattern": source)
def parse_pattern(data: dict | str | bytes, source: str = "pattern") -> PatternSpec:
    """A PatternSpec from JSON text or an already-parsed dict; InputError on anything wrong."""
    if isinstance(data, (str, bytes)):
        try:
            data = json.loads(data)
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise InputError(f"{source}: not valid JSON ({e}); a GarmentCode specification .json is expected") from None
    if not isinstance(data, dict) or "pattern" not in data:
        raise InputError(f"{source}: no 'pattern' object at the top level; a GarmentCode specification "
                         "has {\"pattern\": {\"panels\": ..., \"stitches\": ...}, \"properties\": ...}")
    try:
        return PatternSpec.model_validate(data)
    except ValidationError as e:
        errs = e.errors()
        parts = []
        for err in errs[:3]:
            loc = ".".join(str(x) for x in err["loc"])
            parts.append(f"{loc}: {err['msg']}")
        more = f" (+{len(errs) - 3} more)" if len(errs) > 3 else ""
        raise InputError(f"{source}: invalid pattern: " + "; ".join(parts) + more) from None


@parser("a GarmentCode pattern")
def load_pattern(path: str | Path) -> PatternSpec:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"pattern file not found: {path}")
    if path.stat().st_size > MAX_PATTERN_BYTES:
        raise InputError(f"{path.name}: pattern file larger than {MAX_PATTERN_BYTES // 1_000_000} MB")
    if path.stat().st_size == 0:
        raise InputError(f"{path.name}: empty file")
    return parse_pattern(path.read_bytes(), source=path.name)


def pattern_to_dict(spec: PatternSpec) -> dict:
    return spec.model_dump(mode="json", exclude_none=True)


def save_pattern(spec: PatternSpec, path: str | Path) -> Path:
    path = Path(path)
    path.write_text(json.dumps(pattern_to_dict(spec), indent=2))
    return path


_COLOURS = ["#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#e377c2", "#8c564b", "#bcbd22"]


def pattern_to_svg(spec: PatternSpec, margin_cm: float = 5.0, edge_numbers: bool = False) -> str:
    """Panels laid out side by side (in cm, y up flipped for SVG), stitched edges coloured in
    pairs with their stitch number, panel names in the middle; edge_numbers: every edge's number
    (grey, inside the panel by its middle), the numbers stitches name."""
    scale, rel = spec.scale, spec.properties.curvature_coords == "relative"
    stitch_of: dict[tuple[str, int], int] = {}
    for k, (a, b) in enumerate(spec.pattern.stitches):
        stitch_of[(a.panel, a.edge)] = k
        stitch_of[(b.panel, b.edge)] = k
    items, x_cursor, height = [], margin_cm, 0.0
    for name, panel in spec.pattern.panels.items():
        poly = geo.outline(panel, scale, rel) * 100.0
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        offset = np.array([x_cursor - lo[0], -lo[1]])
        items.append((name, panel, offset, lo, hi))
        x_cursor += (hi[0] - lo[0]) + margin_cm
        height = max(height, hi[1] - lo[1])
    width, height = x_cursor, height + 2 * margin_cm

    def tf(p):  # pattern cm -> svg (y down)
        return p[:, 0], height - margin_cm - p[:, 1]

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.1f}cm" height="{height:.1f}cm" '
           f'viewBox="0 0 {width:.2f} {height:.2f}">',
           '<style>text{font-family:sans-serif}</style>']
    for name, panel, offset, lo, hi in items:
        poly = geo.outline(panel, scale, rel) * 100.0 + offset
        x, y = tf(poly)
        pts = " ".join(f"{a:.2f},{b:.2f}" for a, b in zip(x, y))
        out.append(f'<polygon points="{pts}" fill="#f3e7d3" stroke="#333" stroke-width="0.15"/>')
        centre = poly.mean(axis=0)
        for i, e in enumerate(panel.edges):
            k = stitch_of.get((name, i))
            if not edge_numbers and k is None:
                continue
            seg = geo.edge_samples(panel, e, scale, 32, rel) * 100.0 + offset
            if edge_numbers:
                at = seg[len(seg) // 2]
                at = at + 3.0 * (centre - at) / max(float(np.linalg.norm(centre - at)), 1e-9)  # 3 cm inside
                ex, ey = tf(at[None])
                out.append(f'<text x="{ex[0]:.2f}" y="{ey[0]:.2f}" font-size="2.0" fill="#777" '
                           f'text-anchor="middle">e{i}</text>')
            if k is None:
                continue
            sx, sy = tf(seg)
            c = _COLOURS[k % len(_COLOURS)]
            d = " ".join(f"{a:.2f},{b:.2f}" for a, b in zip(sx, sy))
            out.append(f'<polyline points="{d}" fill="none" stroke="{c}" stroke-width="0.6"/>')
            mid = len(sx) // 2
            out.append(f'<text x="{sx[mid]:.2f}" y="{sy[mid]:.2f}" font-size="2.2" fill="{c}">s{k}</text>')
        cx, cy = tf(poly.mean(axis=0, keepdims=True))
        out.append(f'<text x="{cx[0]:.2f}" y="{cy[0]:.2f}" font-size="2.5" text-anchor="middle">{escape(name)}</text>')
    out.append("</svg>")
    return "\n".join(out)
