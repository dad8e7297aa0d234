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
Which chart: the default bodies' own (default:female / default:male); any other body (a scan,
an uploaded animation) by the sex its shape reads (engine.body.sex: breasts, waist and ribcage
against the hips; by the waist-to-hip ratio alone, 0.80 or more for men, a man with a slim
waist got the women's chart). A file's name does not choose it: the same scan got the men's
chart as "anim_male.zip" and the women's as the service's "body-<id>.zip", whose M skirt could
not be sewn around a man's waist.
Armhole (scye) depth below the shoulder: 0.12 x height for women (Aldrich's women's block,
21 cm at 164 cm), 0.14 x height for men (his men's blocks, ~24-25 cm at 176 cm: a deeper
armhole for the thicker arm root; 0.12 measured 22-33 % strain at the male armpit).
Neckline: half-width 0.045 x height or the body's neck base + 1 cm, whichever is wider (a
muscular neck); front depth 0.8 x 9 cm below the side neck point, back 1.6 cm.
Women's bodices have no bust dart; instead the side seam sits BUST_SHIFT (1.5 cm) behind the
quarter line, so the front is 6 cm wider than the back (a block's front is fuller at the bust;
measured on default:female in M: dress strain 8.0 -> 5.7 %, shirt 6.6 -> 5.5 %).

Each garment is a GarmentCode specification (cm) with a plan of where its panels go
(engine.garment.catalogue places them round the body).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.types import Body
from engine.errors import InputError
from engine.pattern import geometry as geo
from engine.pattern.spec import PanelHint, PatternSpec

SIZES = ("XS", "S", "M", "L", "XL", "XXL")
SCYE_WOMEN, SCYE_MEN = 0.12, 0.14  # armhole depth below the shoulder point, x height ...
# ... or deeper: the armhole's underarm point at least this x Measurements.arm_root below the
# body's armpit (thick arms). Measured: the sample scan's L sleeveless shirt (arm root 34.2 cm,
# underarm 7.6 cm below its armpit) stayed 13 % stretched round the armholes and --size auto
# went on to XL; default:female,gender=0.5,weight=1 (34.8 cm, 5.5 cm) 32 % in M, 16 % in L.
# 2.5 cm deeper, both fit (5.6 and 5.9 %). default:female (29.2 cm, 8.1 cm) and default:male
# (35.5 cm, 10.8 cm) keep their armholes
ARMHOLE_PER_ARM_ROOT = 0.27
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
                e["curvature"] = {"type": "quadratic", "params": [list(geo.to_relative(self.pts[a], self.pts[b], ctrl))]}
            out_edges.append(e)
            index[name] = k
        return ({"translation": list(translation), "rotation": [0.0, 0.0, 0.0],
                 "vertices": [list(p) for p in self.pts], "edges": out_edges}, index)


@dataclass
class Made:
    spec: PatternSpec
    tops: dict[str, float]  # panel -> world height of its v = 0 line (m)
    hints: dict[str, PanelHint]
    sleeve_axes: dict[str, "SleevePlan"]  # sleeve panel -> where it goes on the arm
    clamp_y: float | None
    legs: dict[str, "LegPlan"] | None = None  # trouser panel -> its leg (trousers only)


@dataclass
class SleevePlan:
    side: str  # 'left' (body's left, +x) or 'right'
    cap_top: np.ndarray  # (3,) world point (m) where the top of the cap goes (the shoulder point)
    joints: np.ndarray  # (3, 3) upper arm, elbow, wrist joints (m)


@dataclass
class LegPlan:
    leg: int  # +1 body's left (x > 0), -1 right
    crease: float  # u (m) of the leg's crease line in the panel frame
    crotch_y: float  # world height (m) of the garment's crotch point


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
    # the body's arm joints when it has a rig: side ('left' = +x) -> (3, 3) world points (m) of
    # the upper arm, elbow and wrist joints; None for scans (make_garment fits a skeleton to a
    # scan for the garments that need them)
    arms: dict[str, np.ndarray] | None = None
    men: bool = False
    # the body's lower legs: heights (cm, every cm from 2 to 30) and the hull perimeter (cm) of
    # the wider leg's cut there (trousers: how low a hem opening goes round the foot)
    ankle: tuple[np.ndarray, np.ndarray] | None = None
    # the body's own waist girth (cm): a skirt's or trousers' waistband takes in to it where the
    # size's is larger (waistband_girth)
    body_waist: float | None = None


def waistband_girth(f: Fit) -> float:
    """The waist girth (cm, before ease) of a skirt's or trousers' waistband: the size's, or the
    body's where that is smaller -- a waistband that holds at the waist, as a real one does by
    its tension (taken in, elastic, or belted). A size chosen by the hips would hang loose at a
    slimmer waist and slide down the body to where it is as wide."""
    return min(f.waist, f.body_waist) if f.body_waist is not None and np.isfinite(f.body_waist) else f.waist


def chart_of(body: Body, m=None) -> str:
    """'women' or 'men': the size chart for this body (module doc)."""
    if body.name.startswith("default:"):
        return "men" if body.name.split(",")[0] == "default:male" else "women"
    from engine.body.sex import body_sex

    if m is None:
        from engine.body.measure import measure

        m = measure(body)
    return "men" if body_sex(body, m) == "male" else "women"


# the body girths each garment is cut to fit (the others it does not reach, or hangs free of)
FIT_GIRTHS = {"skirt": ("waist", "hips"), "trousers": ("waist", "hips"), "sleeveless-shirt": ("bust", "hips"),
              "dress": ("bust", "waist", "hips"), "shirt": ("bust", "hips")}
AUTO = "auto"


def recommend_size(name: str, body: Body, m=None) -> str:
    """The smallest size whose chart girths cover the body's, for the girths this garment is cut
    to fit (FIT_GIRTHS): a chart's centre value covers bodies up to half a step above it (the
    next size takes over there), so a body between two sizes gets the larger one. Measured:
    default:female (85/67/98 cm) and default:male (101/83/102 cm) get M, the sample scan
    (98/80/105 cm) L -- its M dress and trousers cannot be sewn round its hips."""
    from engine.body.measure import measure

    if name not in FIT_GIRTHS:
        raise InputError(f"unknown garment '{name}'; the catalogue has: {', '.join(CATALOGUE)}")
    m = m if m is not None else measure(body)
    chart = MEN if chart_of(body, m) == "men" else WOMEN
    keys = ("bust", "waist", "hips")
    have = {k: 100 * getattr(m, k) for k in FIT_GIRTHS[name]}
    bad = [k for k, v in have.items() if not np.isfinite(v)]
    if bad:
        why = f" ({'; '.join(m.notes)})" if m.notes else ""
        raise InputError(f"the body's {', '.join(bad)} could not be measured{why}, so no size can be chosen "
                         "for it: give one (--size M)")

    def covers(i: int, g: str) -> float:  # the largest girth g size i fits: half a step past its own
        col, nxt = keys.index(g), min(i + 1, len(SIZES) - 1)  # (XXL: half the step from XL)
        return chart[SIZES[i]][col] + 0.5 * (chart[SIZES[nxt]][col] - chart[SIZES[nxt - 1]][col])

    for i, size in enumerate(SIZES):
        if all(v <= covers(i, g) for g, v in have.items()):
            return size
    big = ", ".join(f"{g} {v:.0f} cm" for g, v in have.items())
    top = ", ".join(f"{g} {chart[SIZES[-1]][keys.index(g)]} cm" for g in have)
    raise InputError(f"the body ({big}) is larger than the largest size, {SIZES[-1]} ({top})")


def _fit(body: Body, size: str) -> Fit:
    from engine.body.measure import measure

    if size not in SIZES:
        raise InputError(f"size '{size}': choose one of {', '.join(SIZES)} or {AUTO} (from the body's girths)")
    m = measure(body)
    chart = MEN if chart_of(body, m) == "men" else WOMEN
    bust, waist, hips = chart[size]
    need = {"shoulder_height": m.shoulder_height, "waist_height": m.waist_height, "hip_height": m.hip_height,
            "crotch_height": m.crotch_height, "knee_height": m.knee_height}
    bad = [k for k, v in need.items() if not np.isfinite(v)]
    if bad:
        why = f" ({'; '.join(m.notes)})" if m.notes else ""
        raise InputError(f"the body's landmarks ({', '.join(bad)}) could not be measured{why}; catalogue "
                         "garments need them to be placed (check `tryon body info`)")
    sw = m.shoulder_width if np.isfinite(m.shoulder_width) else 0.21 * m.height
    underarm = m.shoulder_height - (SCYE_MEN if chart is MEN else SCYE_WOMEN) * m.height
    if np.isfinite(m.arm_root) and np.isfinite(m.armpit_height):  # thick arms: a deeper armhole
        underarm = min(underarm, m.armpit_height - ARMHOLE_PER_ARM_ROOT * m.arm_root)
    fit = Fit(bust, waist, hips, 100 * m.height, 100 * m.shoulder_height, 100 * m.waist_height,
               100 * m.hip_height, 100 * m.crotch_height, 100 * m.knee_height, 100 * sw, 100 * underarm,
               arm_joints(body), chart is MEN, _ankle_girths(body), 100 * m.waist)
    # the neckline: at least 0.045 x height each side of the centre, wider where the body's neck
    # base is (a muscular neck and trapezius), with 1 cm to spare
    nw = 0.045 * m.height
    nh = _side_neck_height(body, nw, m.shoulder_height)
    base = neck_half_width(body, nh + 0.01)
    if base + 0.01 > nw:
        nw = base + 0.01
        nh = _side_neck_height(body, nw, m.shoulder_height)
    fit.neck_w, fit.neck_h = 100 * nw, 100 * nh
    return fit


def _ankle_girths(body: Body) -> tuple[np.ndarray, np.ndarray]:
    """(heights cm, hull perimeter cm of the wider of the two legs' cuts) from 2 to 30 cm; nan
    where a leg's cut is missing (a hole in a scan)."""
    from engine.body.measure import slice_stack

    ys = np.arange(0.02, 0.305, 0.01)
    per = np.full(len(ys), np.nan)
    for k, pieces in enumerate(slice_stack(body.vertices, body.faces, ys)):
        sides = [max((p for p in pieces if s * p.centroid[0] > 0), key=lambda p: p.length, default=None)
                 for s in (1, -1)]
        if all(p is not None for p in sides):
            per[k] = max(p.hull_perimeter for p in sides)
    return 100 * ys, 100 * per


def neck_half_width(body: Body, y: float) -> float:
    """Half the x-extent (m) of the neck at height y (vertices within 12 cm of the centre line)."""
    v = body.vertices
    s = v[(np.abs(v[:, 1] - y) < 0.005) & (np.abs(v[:, 0]) < 0.12), 0]
    return 0.0 if len(s) == 0 else float(0.5 * (s.max() - s.min()))


def _side_neck_height(body: Body, nw: float, shoulder_h: float) -> float:
    """Height (m) of the body's top surface where the neckline's side point sits (|x| = nw):
    the top of the trapezius, higher above the shoulder point on some bodies than others."""
    v = body.vertices
    sel = (np.abs(np.abs(v[:, 0]) - nw) < 0.01) & (v[:, 1] > shoulder_h - 0.02) & (v[:, 1] < shoulder_h + 0.2)
    if not sel.any():
        return shoulder_h + 0.04
    # the neck itself rises at |x| < nw; at |x| = nw the highest point below the neck's steep
    # wall is the shoulder line: take the highest vertex whose neighbours there are not much higher
    ys = np.sort(v[sel, 1])
    gaps = np.diff(ys)
    cut = np.flatnonzero(gaps > 0.015)  # a jump: the neck's wall above the shoulder line
    top = ys[cut[0]] if len(cut) else ys[-1]
    return float(min(max(top, shoulder_h + 0.02), shoulder_h + 0.10))


ARM_JOINTS = (("upperarm01", "shoulder01"), ("lowerarm01",), ("wrist",))


def arm_joints(body: Body) -> dict[str, np.ndarray] | None:
    """Upper arm, elbow and wrist joint positions of each arm from the rig (None without one)."""
    rig = body.rig
    if rig is None:
        return None
    names = {n: i for i, n in enumerate(rig.joint_names)}
    out = {}
    for side, suffix in (("left", ".L"), ("right", ".R")):
        pts = []
        for options in ARM_JOINTS:
            j = next((names[o + suffix] for o in options if o + suffix in names), None)
            if j is None:
                return None
            pts.append(np.asarray(rig.rest_transforms[j][:3, 3], dtype=np.float64))
        out[side] = np.array(pts)
    return out


# ------------------------------------------------------------------ garments


def skirt(f: Fit) -> Made:
    """A-line skirt, two panels, from the waist to just below the knee."""
    ww, wh = (waistband_girth(f) + 2) / 4, (f.hips + 4) / 4  # half widths of one panel
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


BUST_SHIFT = 1.5  # cm of quarter bust width moved from the back to the front of a woman's bodice


def _bodice(f: Fit, length: float, bust_ease: float, waist_ease: float | None, hip_ease: float,
            flare: float, neck_front: float, shoulder: float = -1.0) -> tuple[Outline, Outline, dict]:
    """Front and back bodice outlines (the front neckline deeper), v = 0 at the neck point;
    side seams split at the underarm, waist and hip levels that lie above the hem.
    shoulder: where the shoulder seam ends, cm beyond the shoulder point (-1: a strap inside it,
    off the deltoid; a sleeved bodice reaches the arm)."""
    nw = getattr(f, "neck_w", 0.045 * f.height)  # half the neckline width
    sw = f.shoulder_w / 2 + shoulder
    slope = max(4.0, getattr(f, "neck_h", f.shoulder_h + 4.0) + 1.0 - f.shoulder_h)  # neck point 1 cm above the body
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

    def one(neck_depth, scoop, bust_shift):
        # scoop: how far inside the underarm point the armhole curve bows (cm); the back is
        # cut fuller than the front, over the shoulder blades
        # bust_shift: cm moved from the back's quarter width to the front's, the side seam moved
        # backwards all the way down (a woman's front is fuller at the bust: without a dart a
        # flat front is stretched over it)
        # quadratic neckline: its lowest point is half the control point's depth (0.8 x neck_depth)
        o = Outline((nw, 0)).curve((0.2 * nw, -1.6 * neck_depth), (-nw, 0), "neck")
        o.line((-sw, -slope), "shoulder_l")
        side_pts = [(u - bust_shift, v) for u, v in left]
        o.curve((-wb - bust_shift + scoop, -0.75 * ad), side_pts[0], "arm_l")
        for i in range(1, n + 1):
            o.line(side_pts[i], f"side_l{i}")
        o.line((-side_pts[n][0], side_pts[n][1]), "hem")
        for i in range(n - 1, -1, -1):
            o.line((-side_pts[i][0], side_pts[i][1]), f"side_r{i + 1}")
        o.curve((wb + bust_shift - scoop, -0.75 * ad), (sw, -slope), "arm_r")
        o.close("shoulder_r")
        return o

    shift = 0.0 if f.men else BUST_SHIFT
    return (one(neck_front, 1.0, shift), one(2.0, -0.5, -shift),
            {"side": side, "top": (f.shoulder_h + slope) / 100})


def _torso_garment(f: Fit, length: float, bust_ease: float, waist_ease, hip_ease: float, flare: float,
                   neck_front: float, shoulder: float = -1.0):
    fo, bo, info = _bodice(f, length, bust_ease, waist_ease, hip_ease, flare, neck_front, shoulder)
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


def _sleeve_outline(width: float, cuff: float, length: float, cap: float) -> Outline:
    """One-piece sleeve (cm): cap top at (0, 0), u around the arm (u > 0 the front half), the
    underarm seam split into its front and back edges, cuff at v = -length."""
    hw, hc = width / 2, cuff / 2
    return (Outline((0, 0)).curve((-0.55 * hw, -0.08 * cap), (-hw, -cap), "cap_b")
            .line((-hc, -length), "seam_b").line((hc, -length), "cuff").line((hw, -cap), "seam_f")
            .close("cap_f", ctrl=(0.55 * hw, -0.08 * cap)))


def _cap_height(width: float, cuff: float, length: float, target: float) -> float:
    """Cap height (cm) whose cap half is `target` cm long (bisection on the built panel)."""
    scale = 0.01

    def half(cap):
        panel, idx = _sleeve_outline(width, cuff, length, cap).panel()
        p = PatternSpec.model_validate({"pattern": {"panels": {"s": panel}, "stitches": []},
                                        "properties": {"units_in_meter": 100, "curvature_coords": "relative"}})
        pan = p.pattern.panels["s"]
        return geo.edge_length(pan, pan.edges[idx["cap_f"]], scale) * 100

    lo, hi = 1.0, 0.6 * length
    if half(lo) > target:
        raise InputError(f"the sleeve ({width:.0f} cm wide) is too wide for the armhole ({target:.0f} cm): "
                         "choose a larger size")
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        if half(mid) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def shirt(f: Fit) -> Made:
    """Shirt with long sleeves: the sleeveless bodice with its shoulders out to the shoulder
    points, plus one-piece sleeves whose caps are sewn into the armholes."""
    if f.arms is None:
        raise InputError("sleeved garments need the body's arm axes, which come from a skeleton, and none "
                         "could be fitted to this body; use the default body, or the sleeveless-shirt")
    length = f.shoulder_h + 4 - f.hip_h + 6
    shoulder = 1.0  # the shoulder seam ends 1 cm past the shoulder point, on the arm
    panels, st, hints, fi, bi, top = _torso_garment(f, length, 10, None, 8, 1.0, 9.0, shoulder)
    spec0 = _spec(dict(panels), [], {})
    front = spec0.pattern.panels["front"]
    armhole = geo.edge_length(front, front.edges[fi["arm_r"]], 0.01) * 100
    back = spec0.pattern.panels["back"]
    armhole = max(armhole, geo.edge_length(back, back.edges[bi["arm_r"]], 0.01) * 100)
    width = 0.31 * f.bust + 8  # bicep girth + ease
    cuff = 26.0 if f.men else 24.0
    sw = f.shoulder_w / 2 + shoulder
    axes = {}
    for side, sgn in (("left", 1.0), ("right", -1.0)):
        j = f.arms[side]
        cap_top = np.array([sgn * sw / 100, f.shoulder_h / 100 + 0.01, j[0, 2]])
        d1 = (j[1] - j[0]) / np.linalg.norm(j[1] - j[0])
        arm_len = 100 * (abs(float((j[1] - cap_top) @ d1)) + float(np.linalg.norm(j[2] - j[1])))
        axes[f"sleeve_{side[0]}"] = (side, cap_top, j, arm_len)
    length_s = max(a[3] for a in axes.values()) + 2.0  # to just past the wrist
    cap = _cap_height(width, cuff, length_s, 1.025 * armhole)
    o = _sleeve_outline(width, cuff, length_s, cap)
    plans = {}
    for name, (side, cap_top, j, _) in axes.items():
        # wrap_sleeve puts u > 0 at the front of either arm; on the body's left arm that makes a
        # counter-clockwise panel face the arm, so that sleeve is drawn clockwise
        panels[name], idx = o.panel(reverse=(side == "left"))
        arm = "arm_r" if side == "left" else "arm_l"  # body's left = u > 0 side of the bodice
        _stitch(st, name, idx["cap_f"], "front", fi[arm])
        _stitch(st, name, idx["cap_b"], "back", bi[arm])
        _stitch(st, name, idx["seam_f"], name, idx["seam_b"])
        hints[name] = PanelHint(region=f"{side}_arm", side="around")
        plans[name] = SleevePlan(side, cap_top, j)
    tops = {"front": top, "back": top, **{n: 0.0 for n in plans}}
    return Made(_spec(panels, st, hints), tops, hints, plans, f.armpit_h / 100)


HEM_LOWEST = 3.0  # cm: the hem at least this far above the floor ...
HEM_ROOM = 10.0  # cm: ... and where the hem opening exceeds the leg's hull perimeter by this much


def _hem_height(f: Fit, hem: float) -> float:
    """Height (cm) of the trousers' hem: the lowest where a hem opening of `hem` cm goes round
    the body's leg with HEM_ROOM to spare (placed on the leg's covering ellipse 2 cm out, it
    starts unstretched). Below the ankle the foot grows fast toward the sole: measured on
    default:female, 22.7 cm round at 10 cm, 35 cm at 5 cm, 47 cm at 3 cm -- a 41 cm hem placed
    3 cm up was wrapped round the foot stretched by up to 75 %, and on the first steps it sprang
    up to the calf and crumpled the legs."""
    if f.ankle is None:
        return HEM_LOWEST
    ys, per = f.ankle
    fits = np.flatnonzero(np.isfinite(per) & (per + HEM_ROOM <= hem) & (ys >= HEM_LOWEST))
    return float(ys[fits[0]]) if len(fits) else HEM_LOWEST


def trousers(f: Fit) -> Made:
    """Trousers, four panels (front and back of each leg), waist to the ankle, with crotch
    extensions (front 1/16, back 1/8 of the hip girth) and the legs centred on crease lines."""
    H, W = f.hips + 6, waistband_girth(f) + 2
    d_hip = f.waist_h - f.hip_h
    d_cr = f.waist_h - f.crotch_h + 2  # crotch point 2 cm below the body's
    d_hip = min(d_hip, d_cr - 6)
    d_knee = f.waist_h - f.knee_h
    hem = float(np.clip(40 + 0.1 * (H - 96), 40, 44))  # full hem opening
    length = f.waist_h - _hem_height(f, hem)
    knee = hem + 6
    parts = {}
    for side, dw, ext in (("front", -1.0, H / 16), ("back", 1.0, H / 8)):
        wq, hq = W / 4 + dw, H / 4 + dw  # front a little narrower than the back
        crease = (hq - ext) / 2
        kq, mq = (knee / 2 + 2 * dw) / 2, (hem / 2 + 2 * dw) / 2  # half widths at knee / hem
        top_cf = d_cr - 1.2 * ext if side == "front" else d_cr - 1.1 * ext
        parts[side] = (wq, hq, ext, crease, kq, mq, top_cf)
    panels, st, hints, legs, idx = {}, [], {}, {}, {}
    for side, (wq, hq, ext, crease, kq, mq, top_cf) in parts.items():
        for leg, lname in ((1, "l"), (-1, "r")):
            def P(u, v, leg=leg):
                return (leg * u, v)

            o = (Outline(P(0, 0)).line(P(0, -top_cf), "centre")
                 .curve(P(0, -d_cr + 0.1 * ext), P(-ext, -d_cr), "crotch")
                 .line(P(crease - kq, -d_knee), "inseam1").line(P(crease - mq, -length), "inseam2")
                 .line(P(crease + mq, -length), "hem").line(P(crease + kq, -d_knee), "outseam2")
                 .line(P(hq, -d_hip), "outseam1").curve(P(hq, -0.5 * d_hip), P(wq, 0), "hipline")
                 .close("waist"))
            # the left panels' outline runs counter-clockwise; mirrored (right) it runs clockwise
            ccw = leg == 1
            name = f"{side}_{lname}"
            panels[name], idx[name] = o.panel(reverse=(ccw if side == "back" else not ccw))
            hints[name] = PanelHint(region="left_leg" if leg == 1 else "right_leg", side=side)
            legs[name] = LegPlan(leg, leg * crease / 100, (f.waist_h - d_cr) / 100)
    for lname in ("l", "r"):
        for e in ("hipline", "outseam1", "outseam2", "inseam1", "inseam2"):
            _stitch(st, f"front_{lname}", idx[f"front_{lname}"][e], f"back_{lname}", idx[f"back_{lname}"][e])
    for side in ("front", "back"):
        for e in ("centre", "crotch"):
            _stitch(st, f"{side}_l", idx[f"{side}_l"][e], f"{side}_r", idx[f"{side}_r"][e])
    tops = {n: f.waist_h for n in panels}
    return Made(_spec(panels, st, hints), tops, hints, {}, None, legs)


CATALOGUE = {
    "skirt": (skirt, "A-line skirt, 2 panels, waist to knee"),
    "sleeveless-shirt": (sleeveless_shirt, "sleeveless shirt, 2 panels, shoulders to hips"),
    "dress": (dress, "sleeveless A-line dress, 2 panels, shoulders to knee"),
    "shirt": (shirt, "shirt with long sleeves, 4 panels (bodice front/back, 2 sleeves), shoulders to hips"),
    "trousers": (trousers, "trousers, 4 panels (front/back of each leg), waist to ankle"),
}
