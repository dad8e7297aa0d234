"""The fabric a DXF pattern is made for, where the pattern says so: a DXF holds no fabric of
its own (its "Fabric:" text is a fabric number), so the garment's cloth is read from what its
pieces say and from their shape. Only a stretch knit is suggested, on one of two grounds:
- the pieces' names, categories or annotations, or the style, use a word of such garments
  (STRETCH_WORDS: leggings, tights, elastane, spandex ...);
- the legs' hems are narrower than any adult foot, which they must still go over: their opening
  is under FOOT_GIRTH_CM (the heel-ankle girth, ISO 8559-1's "heel-ankle circumference",
  averages about 31 cm in adult women and 34 cm in men in the US Army's ANSUR II survey, 2012),
  so the cloth stretches (a woven trouser's hem without a slit is cut wider than the foot).
The suggestion is the drape's fabric where the user chose none; a user's fabric wins.
"""

from __future__ import annotations

import re

import numpy as np

from engine.pattern import geometry as geo
from engine.pattern.dxf_infer import leg_spans, span_points
from engine.pattern.dxf_read import DxfPattern

STRETCH_FABRIC = "stretch_knit"
STRETCH_WORDS = ("LEGGING", "JEGGING", "TIGHTS", "TIGHT", "SPANDEX", "ELASTANE", "ELASTAN", "LYCRA", "STRETCH",
                 "UNITARD", "LEOTARD", "SWIMSUIT", "SWIMWEAR", "BIKESHORT", "YOGA")
FOOT_GIRTH_CM = 28.0  # cm: a leg opening narrower than this must stretch to go over the foot


def _words(text: str | None) -> list[str]:
    return [w for w in re.split(r"[^A-Z]+", (text or "").upper()) if w]


def _said(pattern: DxfPattern) -> str | None:
    """The first text of the pattern (style, a piece's name, category or annotation) that names a
    stretch garment or fibre, quoted; else None."""
    texts = [pattern.style] + [t for p in pattern.pieces for t in (p.name, p.category, p.annotation)]
    for text in texts:
        if any(w in STRETCH_WORDS for w in _words(text)):
            return text
    return None


def suggest_fabric(pattern: DxfPattern, parts: list) -> tuple[str, str] | None:
    """(fabric, why) for a pattern whose pieces say it is a stretch knit (see the module doc),
    else None. parts: the inferred garment's parts (engine.pattern.dxf_infer.Part), for the legs'
    openings."""
    said = _said(pattern)
    if said is not None:
        return STRETCH_FABRIC, f"its pieces say it is a stretch garment ('{said}')"
    legs = [p for p in parts if p.role == "leg"]
    if not legs:
        return None
    hems = [float(geo.polyline_length(span_points(p.outline, leg_spans(p)["hem"]))) for p in legs]
    if max(hems) < FOOT_GIRTH_CM:
        return STRETCH_FABRIC, (f"its legs' openings ({np.mean(hems):.1f} cm round) are narrower than a foot "
                                f"(under {FOOT_GIRTH_CM:.0f} cm): it is cut to stretch, a knit with elastane")
    return None
