"""The built-in catalogue: the seeds' five products (skirt, trousers, sleeveless shirt, shirt
with sleeves, dress) as parametric patterns driven by a size chart and the body's landmarks.

Sizes: girths come from the size chart (what a shop sells), lengths and heights from the body
(where the garment sits). So a size M on a large body is tight, as in a shop.

Size charts (body girths, cm): the control dimensions of EN 13402-3:2013 (bust/chest, waist,
hips), centre values rounded as on common European mass-market charts. Women: XS 82/64/90,
S 86/68/94, M 92/74/100, L 98/80/106, XL 104/86/112, XXL 110/93/118. Men (chest/waist/hips):
XS 86/74/88, S 92/80/94, M 98/86/100, L 104/92/106, XL 110/98/112, XXL 116/106/118.
Ease (garment girth minus body girth) after W. Aldrich, "Metric Pattern Cutting for Women's
Wear", 6th ed. (2015), block tables: fitted skirt waist +2, hips +4; semi-fitted dress bust
+8, waist +6, hips +6; shirt/blouse bust +10, hips +8; trousers waist +2, hips +6.

Each garment is a GarmentCode specification (cm) plus a placement function from the body.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from engine.body.types import Body
from engine.errors import InputError
from engine.pattern import geometry as geo
from engine.pattern.spec import PanelHint, PatternSpec

SIZES = ("XS", "S", "M", "L", "XL", "XXL")
WOMEN = {"XS": (82, 64, 90), "S": (86, 68, 94), "M": (92, 74, 100), "L": (98, 80, 106),
         "XL": (104, 86, 112), "XXL": (110, 93, 118)}
MEN = {"XS": (86, 74, 88), "S": (92, 80, 94), "M": (98, 86, 100), "L": (104, 92, 106),
       "XL": (110, 98, 112), "XXL": (116, 106, 118)}


# ------------------------------------------------------------------ building panels


class Outline:
    """A closed panel outline built edge by edge (cm, y up), counter-clockwise as seen from
    outside for a front panel. Edges get names so stitches can refer to them."""

    def __init__(self, start):
        self.pts = [tuple(map(float, start))]
        self.edges: list[tuple[str, tuple | None]] = []  # (name, quadratic control point abs)

    def line(self, p, name):
        self.pts.append(tuple(map(float, p)))
        self.edges.append((name, None))
        return self

    def curve(self, ctrl, p, name):
        self.pts.append(tuple(map(float, p)))
        self.edges.append((name, tuple(map(float, ctrl))))
        return self

    def close(self, name, ctrl=None):
        self.edges.append((name, None if ctrl is None else tuple(map(float, ctrl))))
        return self

    def panel(self, translation=(0, 0, 0), reverse=False) -> tuple[dict, dict[str, int]]:
        """GarmentCode panel dict and edge name -> index. reverse: clockwise (a back panel,
        whose outside faces -z)."""
        n = len(self.pts)
        assert len(self.edges) == n, "close() the outline first"
        edges = []
        for i, (name, ctrl) in enumerate(self.edges):
            a, b = i, (i + 1) % n
            edges.append((name, a, b, ctrl))
        if reverse:
            edges = [(name, b, a, ctrl) for name, a, b, ctrl in reversed(edges)]
        out_edges, index = [], {}
        for k, (name, a, b, ctrl) in enumerate(edges):
            e = {"endpoints": [a, b]}
            if ctrl is not None:
                e["curvature"] = {"type": "quadratic", "params": [list(_abs_to_rel(self.pts[a], self.pts[b], ctrl))]}
            out_edges.append(e)
            index[name] = k
        return ({"translation": list(translation), "rotation": [0.0, 0.0, 0.0],
                 "vertices": [list(p) for p in self.pts], "edges": out_edges}, index)


def _abs_to_rel(s, e, p):
    s, e, p = np.asarray(s), np.asarray(e), np.asarray(p)
    d = e - s
    perp = np.array([-d[1], d[0]])
    L2 = float(d @ d)
    return float((p - s) @ d / L2), float((p - s) @ perp / L2)


@dataclass
class Made:
    spec: PatternSpec
    tops: dict[str, float]  # panel -> world height of its v = 0 line (m)
    hints: dict[str, PanelHint]
    sleeve_axes: dict[str, tuple[np.ndarray, np.ndarray, float]]  # panel -> (shoulder, wrist, radius)
    clamp_y: float | None


def _stitch(stitches, pa, ea, pb, eb):
    stitches.append([{"panel": pa, "edge": ea}, {"panel": pb, "edge": eb}])


def _spec(panels, stitches, hints, fabric="cotton") -> PatternSpec:
    return PatternSpec.model_validate({
        "pattern": {"panels": panels, "stitches": stitches, "panel_order": list(panels)},
        "properties": {"units_in_meter": 100, "curvature_coords": "relative"},
        "tryon": {"fabric": fabric, "placement": {k: v.model_dump() for k, v in hints.items()}},
    })


# ------------------------------------------------------------------ body facts


@dataclass
class Fit:
    bust: float  # cm, from the size chart
    waist: float
    hips: float
    height: float  # cm, from the body
    shoulder_h: float
    waist_h: float
    hip_h: float
    crotch_h: float
    knee_h: float
    shoulder_w: float
    armpit_h: float


def _fit(body: Body, size: str) -> Fit:
    from engine.body.measure import measure

    if size not in SIZES:
        raise InputError(f"size '{size}': choose one of {', '.join(SIZES)}")
    chart = MEN if "male" in body.name and "female" not in body.name else WOMEN
    bust, waist, hips = chart[size]
    m = measure(body)
    need = {"shoulder_height": m.shoulder_height, "waist_height": m.waist_height, "hip_height": m.hip_height,
            "crotch_height": m.crotch_height, "knee_height": m.knee_height}
    bad = [k for k, v in need.items() if not np.isfinite(v)]
    if bad:
        raise InputError(f"the body's landmarks ({', '.join(bad)}) could not be measured; catalogue "
                         "garments need them to be placed (check `tryon body info`)")
    sw = m.shoulder_width if np.isfinite(m.shoulder_width) else 0.21 * m.height
    return Fit(bust, waist, hips, 100 * m.height, 100 * m.shoulder_height, 100 * m.waist_height,
               100 * m.hip_height, 100 * m.crotch_height, 100 * m.knee_height, 100 * sw,
               100 * (m.shoulder_height - 0.12 * m.height))


# ------------------------------------------------------------------ garments


def skirt(f: Fit) -> Made:
    """A-line skirt, two panels, from the waist to just below the knee."""
    ww, wh = (f.waist + 2) / 4, (f.hips + 4) / 4  # half widths of one panel
    d_hip = f.waist_h - f.hip_h
    length = f.waist_h - f.knee_h + 4
    wm = wh + 0.12 * length  # hem: A-line flare
    o = (Outline((ww, 0)).line((-ww, 0), "waist")
         .curve((-wh, -0.55 * d_hip), (-wh, -d_hip), "side_l_top").line((-wm, -length), "side_l")
         .line((wm, -length), "hem").line((wh, -d_hip), "side_r")
         .close("side_r_top", ctrl=(wh, -0.55 * d_hip)))
    front, fi = o.panel()
    back, bi = o.panel(reverse=True)
    st = []
    for e in ("side_l_top", "side_l", "side_r", "side_r_top"):
        _stitch(st, "front", fi[e], "back", bi[e])
    hints = {"front": PanelHint(region="hips", side="front"), "back": PanelHint(region="hips", side="back")}
    return Made(_spec({"front": front, "back": back}, st, hints), {"front": f.waist_h, "back": f.waist_h},
                hints, {}, None)


def _bodice(f: Fit, length: float, bust_ease: float, waist_ease: float | None, hip_ease: float,
            flare: float, neck_front: float) -> tuple[Outline, Outline, dict]:
    """Front and back bodice outlines (the front neckline deeper), v = 0 at the neck point;
    side seams split at the underarm, waist and hip levels that lie above the hem."""
    nw = 0.045 * f.height
    sw = f.shoulder_w / 2 - 1.0  # strap ends inside the shoulder point (off the deltoid)
    slope = 4.0
    ad = f.shoulder_h + slope - f.armpit_h  # armhole depth below the neck point
    wb = (f.bust + bust_ease) / 4
    left = [(-wb, -ad)]
    d_w = f.shoulder_h + slope - f.waist_h
    d_h = f.shoulder_h + slope - f.hip_h
    if waist_ease is not None and d_w < length - 2:
        left.append((-(f.waist + waist_ease) / 4, -d_w))
    if d_h < length - 2:
        left.append((-(f.hips + hip_ease) / 4, -d_h))
    last = left[-1][0]
    left.append((min(last, -(f.hips + hip_ease) / 4) - flare, -length))
    n = len(left) - 1
    side = [(f"side_l{i + 1}", f"side_r{i + 1}") for i in range(n)]

    def one(neck_depth):
        o = Outline((nw, 0)).curve((0.2 * nw, -1.1 * neck_depth), (-nw, 0), "neck")
        o.line((-sw, -slope), "shoulder_l")
        o.curve((-wb + 1.0, -0.75 * ad), left[0], "arm_l")
        for i in range(1, n + 1):
            o.line(left[i], f"side_l{i}")
        o.line((-left[n][0], left[n][1]), "hem")
        for i in range(n - 1, -1, -1):
            o.line((-left[i][0], left[i][1]), f"side_r{i + 1}")
        o.curve((wb - 1.0, -0.75 * ad), (sw, -slope), "arm_r")
        o.close("shoulder_r")
        return o

    return one(neck_front), one(2.0), {"side": side, "top": (f.shoulder_h + slope) / 100}


def _torso_garment(f: Fit, length: float, bust_ease: float, waist_ease, hip_ease: float, flare: float,
                   neck_front: float):
    fo, bo, info = _bodice(f, length, bust_ease, waist_ease, hip_ease, flare, neck_front)
    front, fi = fo.panel()
    back, bi = bo.panel(reverse=True)
    st = []
    for a, b in info["side"]:
        _stitch(st, "front", fi[a], "back", bi[a])
        _stitch(st, "front", fi[b], "back", bi[b])
    _stitch(st, "front", fi["shoulder_l"], "back", bi["shoulder_l"])
    _stitch(st, "front", fi["shoulder_r"], "back", bi["shoulder_r"])
    hints = {"front": PanelHint(region="torso", side="front"), "back": PanelHint(region="torso", side="back")}
    top = info["top"] * 100
    return {"front": front, "back": back}, st, hints, fi, bi, top


def sleeveless_shirt(f: Fit) -> Made:
    """Sleeveless shirt, two panels, from the shoulders to below the hips."""
    length = f.shoulder_h + 4 - f.hip_h + 6
    panels, st, hints, _, _, top = _torso_garment(f, length, 10, None, 8, 1.0, 9.0)
    return Made(_spec(panels, st, hints), {"front": top, "back": top}, hints, {}, f.armpit_h / 100)


def dress(f: Fit) -> Made:
    """Sleeveless dress, two panels, from the shoulders to the knee, A-line skirt part."""
    length = f.shoulder_h + 4 - f.knee_h + 2
    panels, st, hints, _, _, top = _torso_garment(f, length, 8, 6, 6, 0.1 * (f.hip_h - f.knee_h), 9.0)
    return Made(_spec(panels, st, hints), {"front": top, "back": top}, hints, {}, f.armpit_h / 100)


CATALOGUE = {
    "skirt": (skirt, "A-line skirt, 2 panels, waist to knee"),
    "sleeveless-shirt": (sleeveless_shirt, "sleeveless shirt, 2 panels, shoulders to hips"),
    "dress": (dress, "sleeveless A-line dress, 2 panels, shoulders to knee"),
}


def make_garment(name: str, body: Body, size: str = "M"):
    """(PatternSpec, placement function, display name) of a catalogue garment on this body."""
    from engine.garment.place import BodySections, wrap_torso

    if name not in CATALOGUE:
        raise InputError(f"unknown garment '{name}'; the catalogue has: {', '.join(CATALOGUE)}")
    made = CATALOGUE[name][0](_fit(body, size))
    sections = BodySections(body)
    scale = made.spec.scale
    outlines = {n: geo.outline(p, scale) for n, p in made.spec.pattern.panels.items()}

    def place(pname, panel, uv):
        hint = made.hints[pname]
        return wrap_torso(uv, hint, sections, made.tops[pname] / 100.0, outlines[pname], clamp_y=made.clamp_y)

    return made.spec, place, f"{name} ({size})"
