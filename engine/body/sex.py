"""A body's sex from its shape, for the size chart and the skeleton a scan is fitted with.

    body_sex(body, m)  -> "female" | "male"

Three cues, from the mesh alone and independent of its units, pose and density:
- breasts: the area of the front of the chest facing down (the underside of the breasts,
  above the inframammary fold), per mille of the height squared, where the surface's normals
  are averaged over NORMAL_CELL (a scanner's noise on a dense mesh must not read as faces
  looking down);
- the waist-to-hip girth ratio (men carry their weight at the waist);
- the underbust-to-hip girth ratio (a woman's ribcage is narrow for her hips; the underbust
  where there is none stands for it in the waist-hip ratio's place).
score = BREAST x breasts - WAIST_HIP x (waist/hips - 0.8) - RIBS_HIP x (underbust/hips - 0.8)
+ OFFSET; female above 0. The weights are a logistic regression's on the default bodies, rounded
(docs/tuning.md: what they separate and what not).
"""

from __future__ import annotations

import numpy as np

from engine.body.types import Body

NORMAL_CELL = 0.02  # m: normals averaged over cubes of this size
DOWN = -0.35  # a face looks down when its averaged normal's y is below this
BREAST, WAIST_HIP, RIBS_HIP, OFFSET = 0.4, 14.0, 26.0, -0.6
UNSURE = 0.5  # |score| below this: said in a note


def sex_score(body: Body, m) -> float:
    """The score of the module doc (NaN when the waist, hips or armpits were not measured)."""
    if not all(np.isfinite([m.waist, m.hips, m.waist_height, m.armpit_height])):
        return float("nan")
    wh = m.waist / m.hips
    ribs = m.underbust / m.hips if np.isfinite(m.underbust) else wh
    return BREAST * breast_area(body, m) - WAIST_HIP * (wh - 0.8) - RIBS_HIP * (ribs - 0.8) + OFFSET


def body_sex(body: Body, m) -> str:
    """'female' or 'male' (module doc); 'female' when the score cannot be computed."""
    s = sex_score(body, m)
    return "male" if np.isfinite(s) and s < 0 else "female"


def sex_note(body: Body, m) -> str | None:
    """A line for the notes when the cues barely decide (or could not be read)."""
    s = sex_score(body, m)
    if not np.isfinite(s):
        return "the body's sex could not be read from its shape (no waist, hips or armpits): taken as female"
    if abs(s) < UNSURE:
        return (f"the body's sex read from its shape with low confidence ({body_sex(body, m)}: breasts, waist and "
                "ribcage against the hips barely decide)")
    return None


def breast_area(body: Body, m) -> float:
    """Area (per mille of height^2) of the chest's front facing down: faces in the upper 70 % of
    the span from the waist to the armpits, in front of the torso's middle, within 16 % of the
    height (left and right) of the body's axis, whose cell-averaged normal has y < DOWN and z > 0."""
    v, f = np.asarray(body.vertices, np.float64), np.asarray(body.faces, np.int64)
    h = float(v[:, 1].max() - v[:, 1].min())
    t = v[f]
    c = t.mean(axis=1)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])  # twice the area along the normal
    area = 0.5 * np.linalg.norm(n, axis=1)
    lo = m.waist_height + 0.3 * (m.armpit_height - m.waist_height)
    band = (c[:, 1] > m.waist_height) & (c[:, 1] < m.armpit_height)
    ax = float(np.median(c[band, 0])) if band.any() else 0.0
    near = band & (np.abs(c[:, 0] - ax) < 0.1 * h)
    zc = float(np.median(c[near, 2])) if near.any() else 0.0
    region = (c[:, 1] > lo) & (c[:, 1] < m.armpit_height) & (c[:, 2] > zc) & (np.abs(c[:, 0] - ax) < 0.16 * h / 1.7)
    if not region.any():
        return 0.0
    nn = _cell_normals(c, n, NORMAL_CELL)
    down = region & (nn[:, 1] < DOWN) & (nn[:, 2] > 0.0)
    return float(area[down].sum() / (h * h) * 1000.0)


def _cell_normals(c: np.ndarray, n: np.ndarray, cell: float) -> np.ndarray:
    """Each face's normal replaced by the unit sum of the (area-weighted) normals of all faces
    whose centres share its cube of side `cell`."""
    key = np.floor(c / cell).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.ravel()
    s = np.zeros((inv.max() + 1, 3))
    np.add.at(s, inv, n)
    out = s[inv]
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-20)
