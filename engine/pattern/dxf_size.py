"""Which of a DXF pattern's graded sizes fits a body, from its girths against the pieces' widths.

A top's chest is the width of its front and back panels 2 cm below their underarm points; a
bottom's hips are twice the width of its leg panel halfway from the waist down to the crotch.
The size chosen is the smallest whose garment girth is at least the body's plus the ease a
woven cloth needs to go on (EASE_CM); `--size auto` then drapes it, and the next larger sizes
where it comes out too small (engine.scene.garments.dress_in_size).
"""

from __future__ import annotations

import numpy as np

from engine.errors import InputError
from engine.pattern.dxf_infer import infer, point_at
from engine.pattern.dxf_read import DxfPattern
from engine.pattern.geometry import row_extent

EASE_CM = {"chest": 6.0, "hips": 2.0}  # garment girth less body girth, at least


def _width_at(outline: np.ndarray, v: float) -> float:
    lo, hi = row_extent(outline, np.array([v]))
    return float(hi[0] - lo[0])


def garment_girth(pattern: DxfPattern, size: str) -> tuple[str, float] | None:
    """('chest' or 'hips', the garment's girth there in cm) in one size, None when no garment is
    inferred."""
    inf = infer(pattern, size)
    if inf.kind == "top":
        total = 0.0
        for p in inf.parts:
            if p.role in ("front", "back"):
                v = min(point_at(p.outline, p.marks[k])[1] for k in ("up_l", "up_r")) - 2.0
                total += _width_at(p.outline, v)
        return "chest", total
    if inf.kind == "bottom":
        leg = next(p for p in inf.parts if p.role == "leg")
        v = 0.5 * point_at(leg.outline, leg.marks["cf"])[1]
        return "hips", 2.0 * _width_at(leg.outline, v)
    return None


def recommend_size(pattern: DxfPattern, body_girths: dict[str, float]) -> tuple[str, str]:
    """(the size, why) for a body's girths (cm: 'chest', 'hips')."""
    girths = {s: garment_girth(pattern, s) for s in pattern.sizes}
    known = {s: g for s, g in girths.items() if g is not None}
    if not known:
        raise InputError(f"{pattern.source}: no garment could be inferred, so no size can be chosen: give one "
                         f"(its sizes: {', '.join(pattern.sizes)})")
    where = next(iter(known.values()))[0]
    body = body_girths.get(where, float("nan"))
    if not np.isfinite(body):
        raise InputError(f"the body's {where} could not be measured, so no size can be chosen: give one "
                         f"(--size {pattern.sizes[len(pattern.sizes) // 2]})")
    need = body + EASE_CM[where]
    for s, g in known.items():
        if g[1] >= need:
            return s, (f"the smallest size whose {where} ({g[1]:.0f} cm) is the body's ({body:.0f} cm) + "
                       f"{EASE_CM[where]:.0f} cm or more")
    last = list(known)[-1]
    raise InputError(f"the body's {where} ({body:.0f} cm) is larger than the largest size's, {last} "
                     f"({known[last][1]:.0f} cm)")
