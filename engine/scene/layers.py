"""Whether a garment's parts may come to lie on each other -- a collar on the neckline, a cuff over
its sleeve, a skirt level over the next -- so that its cloth needs contact with itself
(engine.cloth.selfcontact, at a cost per step): DrapeTuning.self_contact "auto" asks this. Yes when
panels are placed on each other: a share of the vertices lies within layer_gap of another panel
while far along its own panel from every seam (near a seam, two panels meet by design). A flat
layout whose parts only come to lie on each other while sewing (a collar folding onto the
neckline) is not told by this; DrapeTuning.self_contact = "on" forces the pass.

    on, why = needs_self_contact(garment, tuning)
"""

from __future__ import annotations

import numpy as np

from engine.garment.garment import Garment
from engine.scene.tuning import Tuning


def overlapping_share(garment: Garment, gap: float, clear: float) -> float:
    """The share of the vertices within `gap` of another panel's vertex (as placed) and farther
    than `clear` along their own panel from every stitched vertex of it."""
    from scipy.spatial import cKDTree

    x, uv, panel = garment.positions, garment.uv, garment.panel
    stitched = np.unique(garment.seams.ravel())
    near, free = np.zeros(len(x), dtype=bool), np.ones(len(x), dtype=bool)
    for p in np.unique(panel):
        mine = panel == p
        if mine.all():
            break
        d, _ = cKDTree(x[mine]).query(x[~mine], distance_upper_bound=gap)
        near[~mine] |= d < gap
        own = stitched[panel[stitched] == p]
        if len(own):
            d, _ = cKDTree(uv[own]).query(uv[mine], distance_upper_bound=clear)
            free[mine] = d >= clear
    return float(np.count_nonzero(near & free)) / max(len(x), 1)


def needs_self_contact(garment: Garment, tuning: Tuning) -> tuple[bool, str]:
    """(on, why) of cloth-cloth contact within this garment, as DrapeTuning.self_contact says."""
    t = tuning.drape
    if t.self_contact != "auto":
        return t.self_contact == "on", "asked for"
    share = overlapping_share(garment, t.layer_gap, t.layer_clear)
    if share >= t.layer_share:
        return True, (f"{100 * share:.0f} % of the cloth is placed within {100 * t.layer_gap:g} cm of another "
                      "panel, away from the seams")
    return False, f"no panel placed on another ({100 * share:.1f} % of the cloth)"
