"""Body measurements from geometry alone: horizontal slices of the mesh, cut into pieces.

Works on any normalised Body (world frame of DESIGN.md: metres, Y up, facing +Z, feet on
y = 0). Scans have no segments or rig, so nothing here needs them.
"""

from __future__ import annotations

import copy
import hashlib
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError


# --------------------------------------------------------------------------- slicing


@dataclass
class Piece:
    """One connected curve of a horizontal cut: a loop around a limb or the torso.

    points: (K, 2) float64 (x, z) of the cut points, unordered; length: length of the cut curve
    (what a tape pressed into every concavity would read); centroid: (2,) length-weighted centre
    of the curve; closed: every point has two neighbours (no hole crossed the cut).
    """

    points: np.ndarray
    length: float
    centroid: np.ndarray
    closed: bool
    _hull: float | None = field(default=None, repr=False)

    @property
    def xmin(self) -> float:
        return float(self.points[:, 0].min())

    @property
    def xmax(self) -> float:
        return float(self.points[:, 0].max())

    @property
    def hull_perimeter(self) -> float:
        """Perimeter of the convex hull: a tape measure spans concavities (between the breasts)."""
        if self._hull is None:
            self._hull = hull_perimeter(self.points)
        return self._hull


def hull_perimeter(points: np.ndarray) -> float:
    """Perimeter of the 2D convex hull of (K, 2) points (0 for fewer than 3 / collinear)."""
    if len(points) < 3:
        return 0.0
    try:
        return float(ConvexHull(points).area)  # in 2D qhull's "area" is the perimeter
    except QhullError:
        return 0.0


def slice_pieces(vertices: np.ndarray, faces: np.ndarray, y: float,
                 face_y: np.ndarray | None = None) -> list[Piece]:
    """Cut the mesh with the plane at height y and split the cut into connected pieces.

    Vectorised over all triangles. A vertex exactly on the plane counts as below it, which is
    the same as moving the plane up by an infinitesimal amount: no special cases.
    face_y: (F, 3) y of each face corner, precomputed when slicing many times.
    """
    if face_y is None:
        face_y = vertices[:, 1][faces]
    above = face_y > y
    n_above = above.sum(axis=1)
    sel = (n_above == 1) | (n_above == 2)
    if not sel.any():
        return []
    f = faces[sel].astype(np.int64)
    a = above[sel]
    # Edge k runs from corner k to corner k+1; exactly two of the three edges cross.
    crosses = a != np.roll(a, -1, axis=1)
    skip = np.argmin(crosses, axis=1)
    rows = np.arange(len(f))
    n = len(vertices)

    def edge_key(e):
        i, j = f[rows, e], f[rows, (e + 1) % 3]
        return np.minimum(i, j) * n + np.maximum(i, j)

    keys = np.concatenate([edge_key((skip + 1) % 3), edge_key((skip + 2) % 3)])
    # Each crossed mesh edge is one cut point, shared by the two triangles on either side.
    ukey, inv = np.unique(keys, return_inverse=True)
    p0, p1 = vertices[ukey // n], vertices[ukey % n]
    t = (y - p0[:, 1]) / (p1[:, 1] - p0[:, 1])
    pts = (p0 + t[:, None] * (p1 - p0))[:, [0, 2]]
    m = len(f)
    s1, s2 = inv[:m], inv[m:]
    npts = len(ukey)
    graph = coo_matrix((np.ones(m, np.int8), (s1, s2)), shape=(npts, npts))
    ncomp, label = connected_components(graph, directed=False)
    seg_len = np.linalg.norm(pts[s1] - pts[s2], axis=1)
    seg_mid = 0.5 * (pts[s1] + pts[s2])
    seg_lab = label[s1]
    comp_len = np.bincount(seg_lab, seg_len, ncomp)
    w = np.maximum(comp_len, 1e-30)
    cx = np.bincount(seg_lab, seg_len * seg_mid[:, 0], ncomp) / w
    cz = np.bincount(seg_lab, seg_len * seg_mid[:, 1], ncomp) / w
    degree = np.bincount(s1, minlength=npts) + np.bincount(s2, minlength=npts)
    n_open = np.bincount(label, degree != 2, ncomp)
    order = np.argsort(label, kind="stable")
    bounds = np.searchsorted(label[order], np.arange(ncomp + 1))
    return [Piece(points=pts[order[bounds[c]:bounds[c + 1]]], length=float(comp_len[c]),
                  centroid=np.array([cx[c], cz[c]]), closed=bool(n_open[c] == 0))
            for c in range(ncomp)]


def slice_stack(vertices: np.ndarray, faces: np.ndarray, ys: np.ndarray) -> list[list[Piece]]:
    """slice_pieces at many heights; each triangle is handed only to the cuts it spans, so the
    cost grows with the number of crossings, not with heights x triangles."""
    ys = np.asarray(ys, dtype=np.float64)
    face_y = vertices[:, 1][faces]
    lo, hi = face_y.min(axis=1), face_y.max(axis=1)
    # Cut k crosses a face when lo <= ys[k] < hi (vertex on the plane counts as below).
    first = np.searchsorted(ys, lo, side="left")
    last = np.searchsorted(ys, hi, side="left")  # exclusive
    count = np.maximum(last - first, 0)
    face_idx = np.repeat(np.arange(len(faces)), count)
    offs = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    cut_idx = np.repeat(first, count) + offs
    order = np.argsort(cut_idx, kind="stable")
    face_idx, cut_idx = face_idx[order], cut_idx[order]
    bounds = np.searchsorted(cut_idx, np.arange(len(ys) + 1))
    out = []
    for k, y in enumerate(ys):
        fi = face_idx[bounds[k]:bounds[k + 1]]
        out.append(slice_pieces(vertices, faces[fi], float(y), face_y[fi]) if len(fi) else [])
    return out


# --------------------------------------------------------------------------- measurements

# Order of the report, with labels; every value is a length in metres internally.
FIELDS = (
    ("height", "Height"),
    ("bust", "Bust (chest) circumference"),
    ("underbust", "Underbust circumference"),
    ("waist", "Waist circumference"),
    ("hips", "Hip circumference"),
    ("shoulder_width", "Shoulder width"),
    ("arm_length", "Arm length"),
    ("inseam", "Inseam"),
    ("shoulder_height", "Shoulder height"),
    ("bust_height", "Bust height"),
    ("waist_height", "Waist height"),
    ("hip_height", "Hip height"),
    ("crotch_height", "Crotch height"),
    ("knee_height", "Knee height"),
)


@dataclass
class Measurements:
    """Body measurements in metres (NaN where the geometry did not allow one).

    Definitions (all from the mesh alone; circumferences are horizontal and are the perimeter
    of the convex hull of the torso's cut, i.e. a tape that spans concavities):
      height          top of the head minus the floor (lowest point).
      bust            largest torso circumference between the underbust and just below the
                      armpits (the chest region); for a flat chest this is the chest girth.
      underbust       torso circumference where the steep fall of the girth below the bust ends
                      (the knee of the girth profile between the bust point and the waist).
      waist           smallest torso circumference between the hips and the bust point
                      (the natural waist).
      hips            largest circumference between the crotch and the waist, both legs
                      together just below the crotch.
      shoulder_width  straight distance, left to right, between the acromion points, taken
                      (heuristically) above the side walls of the torso just below the armpits.
      arm_length      acromion to wrist (narrowest arm cut above the hand), along the arm (via
                      the elbow).
      inseam          crotch to floor (crotch_height).
      *_height        height above the floor of: the acromion (shoulder), the most forward point of
                      the bust (bust), the waist, hip and knee cuts, the crotch (highest point where
                      the legs separate).
    """

    height: float = float("nan")
    bust: float = float("nan")
    underbust: float = float("nan")
    waist: float = float("nan")
    hips: float = float("nan")
    shoulder_width: float = float("nan")
    arm_length: float = float("nan")
    inseam: float = float("nan")
    shoulder_height: float = float("nan")
    bust_height: float = float("nan")
    waist_height: float = float("nan")
    hip_height: float = float("nan")
    crotch_height: float = float("nan")
    knee_height: float = float("nan")
    # not printed: for placing and simulating garments
    armpit_height: float = float("nan")  # where the arms join the torso (_find_armpit)
    arm_gap: float = float("nan")  # ARM_GAP_BELOW under the armpits: the narrower of the two
    # gaps between the torso and an arm (0: an arm touches the torso; NaN: no arm hangs there)
    arm_root: float = float("nan")  # ARM_ROOT_BELOW under the armpits: the mean perimeter (convex
    # hull) of the two arms' horizontal cuts -- oblique on an arm held out, so larger than the
    # arm's girth; how thick the arm is where an armhole goes round it
    hand_gap: float = float("nan")  # the smallest gap between an arm hanging below the waist and
    # the torso or legs beside it (0 where they touch or overlap; NaN: no arm reaches there)
    # each measured arm's (acromion, wrist) points (3,) m, y from the floor: the hand lies past
    # the wrist along that line (a sleeve longer than the arm ends over it)
    arm_lines: list = field(default_factory=list, compare=False, repr=False)
    notes: list[str] = field(default_factory=list)
    estimated: list[str] = field(default_factory=list)  # landmarks not found, estimated from the stature

    def to_dict(self) -> dict:
        """Centimetres rounded to 0.1 (None where not measurable), plus "units": "cm"."""
        out: dict = {}
        for key, _ in FIELDS:
            val = getattr(self, key)
            out[key] = None if not np.isfinite(val) else round(float(val) * 100.0, 1)
        out["units"] = "cm"
        if self.notes:
            out["notes"] = list(self.notes)
        return out

    def to_text(self) -> str:
        d = self.to_dict()
        width = max(len(label) for _, label in FIELDS)
        lines = [f"{'Measurement':<{width}}  {'cm':>7}", "-" * (width + 9)]
        for key, label in FIELDS:
            val = d[key]
            lines.append(f"{label:<{width}}  {'n/a' if val is None else f'{val:7.1f}':>7}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


STEP = 0.005  # m between profile cuts; landmarks are then refined by bisection
ARMPIT_CUTS = 3  # the armpits: where the torso cut widens by a quarter within this many cuts up
# ... and below that, cuts still narrowing faster than this (m of width per m of height) going
# down are the fold of skin under a raised arm, not yet the torso (a torso widens more slowly)
FOLD_NARROWING = 1.6
ARM_GAP_BELOW = 0.10  # m below the armpits where Measurements.arm_gap is taken
ARM_ROOT_BELOW = 0.03  # m below the armpits where Measurements.arm_root is taken
# The gap from which the seams beside the arms (over the shoulders, under the arms) are sewn
# reliably (engine.scene.garments.arms_in_the_way). Measured with the dress on bodies whose arms
# were lowered with the default skeleton (for the scan, its fitted one): the sample scan
# (11.2 cm) and default:female (12.7 cm) sew; with the arms 10 degrees closer (7.2, 8.7 cm) a
# shoulder seam stayed 1.8 and 16.5 cm open, at 20 degrees (3.7, 5.4 cm) 2.1 and 15.4 cm, at 30
# (0.9, 2.4 cm) 7-10 and 3.9 cm (the sample scan at 30 degrees in L, XL and XXL alike,
# default:female at 20 in M, L and XL; the others in one size). The strap's front half, pulled
# straight towards its back half (engine.cloth.welds.pull_seams), meets the shoulder where it
# turns into the arm and slides off (object-space collision too). Lifting the strap pairs while
# they close sewed the 10-degree bodies but left tucks across default shirts (not adopted);
# so did lifting the placed straps' ends above the shoulder (the strained straps sprang down).
# Below this gap the panels are sewn with friction (engine.scene.tryon.ARMS_CLOSE_SEW_FRICTION),
# which sews default:female's dress at 10 and 20 degrees but not at 30 nor the sample's at 10
ARM_GAP_OK = 0.10


class _Profile:
    """Horizontal cuts of the body every STEP metres, with the torso piece picked per cut."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, axis_x: float):
        self.v, self.f, self.ax = vertices, faces, axis_x
        self.ys = np.arange(STEP, vertices[:, 1].max(), STEP)
        self.cuts = slice_stack(vertices, faces, self.ys)
        self.central = [self.central_piece(p) for p in self.cuts]

    def central_piece(self, pieces: list[Piece]) -> Piece | None:
        """The piece around the body axis: the longest whose x-range spans the axis (an inner
        cavity such as the mouth is spanned too but is shorter than the head around it)."""
        spans = [p for p in pieces if p.xmin <= self.ax <= p.xmax]
        return max(spans, key=lambda p: p.length) if spans else None

    def cut(self, y: float) -> list[Piece]:
        return slice_pieces(self.v, self.f, y)

    def index_range(self, y0: float, y1: float) -> np.ndarray:
        return np.nonzero((self.ys >= y0) & (self.ys <= y1))[0]

    def girth(self, i: int) -> float:
        p = self.central[i]
        return p.hull_perimeter if p is not None else float("nan")


def _bisect(pred, y_true: float, y_false: float, tol: float = 5e-4) -> float:
    """Boundary between a height where pred holds and one where it does not."""
    for _ in range(40):
        if abs(y_true - y_false) <= tol:
            break
        mid = 0.5 * (y_true + y_false)
        if pred(mid):
            y_true = mid
        else:
            y_false = mid
    return 0.5 * (y_true + y_false)


def _weighted_median(x: np.ndarray, w: np.ndarray) -> float:
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    return float(x[order][np.searchsorted(cw, 0.5 * cw[-1])])


_CACHE: "OrderedDict[bytes, Measurements]" = OrderedDict()
CACHE_SIZE = 8  # bodies whose measurements are kept (a try-on measures its body 3-6 times, ~1 s each)


def measure(body) -> Measurements:
    """Measure a normalised Body (see Measurements for the definitions used). The result is
    cached by the mesh's content (a digest of its vertex and face bytes), so asking again for
    the same mesh -- the size chart, the pattern, the fit check of one try-on -- costs ~1 ms;
    the caller gets its own copy."""
    key = _digest(body)
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return copy.deepcopy(_CACHE[key])
    m = _measure(body)
    _CACHE[key] = copy.deepcopy(m)
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return m


def _digest(body) -> bytes:
    h = hashlib.blake2b(digest_size=16)
    for a in (np.ascontiguousarray(body.vertices, dtype=np.float64), np.ascontiguousarray(body.faces, dtype=np.int64)):
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.digest()


def _measure(body) -> Measurements:
    v = np.asarray(body.vertices, dtype=np.float64)
    f = np.asarray(body.faces, dtype=np.int64)
    m = Measurements()
    y0 = float(v[:, 1].min())
    if y0 != 0.0:  # measure from the floor even if a caller hands an unnormalised body
        v = v - np.array([0.0, y0, 0.0])
    h = float(v[:, 1].max())
    m.height = h
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    # Body axis: area-weighted median x, robust to one arm held out.
    ax = _weighted_median(tri[:, :, 0].mean(axis=1), area)
    prof = _Profile(v, f, ax)

    crotch = _find_crotch(prof, h, m)
    if not np.isfinite(crotch):  # legs together: the girths below it go round both
        crotch = _estimated(m, "crotch height", PROPORTIONS["crotch"] * h)
    m.crotch_height = m.inseam = crotch

    armpit = _find_armpit(prof, h, crotch, m)
    if not np.isfinite(armpit):  # arms pressed to the torso all along: its girths take them in
        armpit = _estimated(m, "armpit height", PROPORTIONS["armpit"] * h)

    m.armpit_height = armpit
    m.arm_gap = _arm_gap(prof, armpit - ARM_GAP_BELOW)
    m.arm_root = _arm_root(prof, armpit - ARM_ROOT_BELOW)
    if m.arm_gap < ARM_GAP_OK:
        m.notes.append(f"the arms hang {100 * m.arm_gap:.1f} cm from the torso {100 * ARM_GAP_BELOW:.0f} cm below "
                       f"the armpits: dresses and tops are sewn reliably from {100 * ARM_GAP_OK:.0f} cm (an "
                       "A-pose, arms about 45 degrees from the body), so the arms are turned out that far "
                       "for dressing and walking (where they cannot be, tops are sewn with friction, and "
                       "where the seams beside the arms do not close, sewn again with the arms raised and "
                       "then lowered)")
    _torso_girths(prof, h, crotch, armpit, m)
    m.hand_gap = _hand_gap(prof, armpit, m.waist_height)
    _knee(prof, h, crotch, m)
    acromion = _shoulders(v, f, prof, h, armpit, m)
    if acromion is not None:
        _arms(v, f, prof, armpit, acromion, m)
    else:
        m.shoulder_height = _estimated(m, "shoulder height", armpit + PROPORTIONS["shoulder_over_armpit"] * h)
    return m


# Where a landmark is not found, its height is estimated from the stature (and the armpits), so that
# what needs it (a garment's placement) can go on; the notes say which
PROPORTIONS = {"crotch": 0.46, "armpit": 0.755, "shoulder_over_armpit": 0.075}


def _estimated(m: Measurements, what: str, value: float) -> float:
    m.notes.append(f"{what} estimated as {100 * value:.1f} cm from the stature (not found: see above)")
    m.estimated.append(what)
    return float(value)


def _find_crotch(prof: _Profile, h: float, m: Measurements) -> float:
    """Highest height where no piece spans the body axis (the legs have separated)."""
    idx = prof.index_range(0.3 * h, 0.65 * h)
    has_central = np.array([prof.central[i] is not None for i in idx])
    if len(idx) == 0 or has_central.all() or not has_central.any():
        m.notes.append("could not find the crotch: the legs are not apart from each other (a scan with the legs "
                       "together, or a long skirt)")
        return float("nan")
    # Scan down from the top of the window: the first cut without a central piece.
    top_true = np.nonzero(has_central)[0].max()
    below = [k for k in range(top_true, -1, -1) if not has_central[k]]
    if not below:
        m.notes.append("could not find the crotch: no cut where the legs are apart")
        return float("nan")
    k = below[0]
    y_false = prof.ys[idx[k]]
    y_true = prof.ys[idx[k + 1]]
    return _bisect(lambda y: prof.central_piece(prof.cut(y)) is not None, y_true, y_false)


def _find_armpit(prof: _Profile, h: float, crotch: float, m: Measurements) -> float:
    """Highest height (below the shoulders) where the central piece narrows sharply going
    down: the arms separate from the torso there (or, in a T-pose, the arms end)."""
    idx = prof.index_range(crotch + 0.1 * h, 0.9 * h)
    width = np.array([(p.xmax - p.xmin) if (p := prof.central[i]) is not None else np.nan for i in idx])
    # cut k much narrower than one of the ARMPIT_CUTS cuts above it: arms held close to the body
    # join the torso one after the other, a cut apart (a scan with its arms 30 degrees closer
    # than the sample's A-pose: widths 32, 40, 47 cm, no single step below 0.8)
    above = np.full((ARMPIT_CUTS, len(width)), -np.inf)  # width of the j-th cut above (-inf: none)
    for j in range(1, ARMPIT_CUTS + 1):
        above[j - 1, :-j] = np.nan_to_num(width[j:], nan=-np.inf)
    with np.errstate(invalid="ignore"):
        drop = width < 0.8 * above.max(axis=0)
    ks = np.nonzero(drop)[0]
    if len(ks) == 0:
        m.notes.append("could not find the armpits: the torso does not narrow under the arms anywhere (arms pressed "
                       "to the torso all along?); the chest and waist may take the arms in")
        return float("nan")
    k = ks.max()
    j = 1 + int(np.argmax(above[:, k]))
    w_lo, w_hi = width[k], width[k + j]
    thresh = 0.5 * (w_lo + w_hi)

    def narrow(y):
        p = prof.central_piece(prof.cut(y))
        return p is not None and (p.xmax - p.xmin) < thresh

    below = k
    while below > 0 and width[below] - width[below - 1] > FOLD_NARROWING * STEP:
        below -= 1
    if below < k:  # the fold of skin between arm and torso (raised arms): the torso starts under it
        return float(prof.ys[idx[below]])
    return _bisect(narrow, prof.ys[idx[k]], prof.ys[idx[k + j]])


def _arm_gap(prof: _Profile, y: float) -> float:
    """The narrower horizontal gap between the torso's cut at height y and the arm beside it on
    either side; for an arm's cut that overlaps the torso's in x (pressed against it, or into
    it), the smallest distance between their points (~0); 0 where no separate arm is cut beside
    the torso but the torso cut is much wider than in the cut 2 cm below (the arm touches it);
    NaN where no arm hangs at that height (a T-pose)."""
    from scipy.spatial import cKDTree

    pieces = prof.cut(y)
    core = prof.central_piece(pieces)
    if core is None:
        return float("nan")
    below = prof.central_piece(prof.cut(y - 0.02))
    merged = below is not None and (core.xmax - core.xmin) > 1.25 * (below.xmax - below.xmin)
    gaps = []
    for side, arms in zip((-1.0, 1.0), _beside(pieces, core)):
        pressed = [p for p in _arm_pieces(prof, pieces, core, side) if all(p is not q for q in arms)]
        if arms:
            gaps.append(min((p.xmin - core.xmax) if side > 0 else (core.xmin - p.xmax) for p in arms))
        elif pressed:
            gaps.append(float(cKDTree(core.points).query(np.vstack([p.points for p in pressed]))[0].min()))
        elif merged:
            gaps.append(0.0)
    return float(min(gaps)) if gaps else float("nan")


def _beside(pieces: list[Piece], core: Piece) -> list[list[Piece]]:
    """The pieces wholly left (-x) and wholly right (+x) of the torso's piece `core`."""
    return [[p for p in pieces if p is not core and (p.xmin > core.xmax if s > 0 else p.xmax < core.xmin)]
            for s in (-1.0, 1.0)]


def _arm_root(prof: _Profile, y: float) -> float:
    """Mean convex-hull perimeter of the longest piece beside the torso on each side at height y
    (the arms); NaN unless both are there."""
    pieces = prof.cut(y)
    core = prof.central_piece(pieces)
    if core is None:
        return float("nan")
    sides = _beside(pieces, core)
    if not all(sides):
        return float("nan")
    return float(np.mean([max(ps, key=lambda p: p.length).hull_perimeter for ps in sides]))


def _torso_girths(prof: _Profile, h: float, crotch: float, armpit: float, m: Measurements) -> None:
    # Bust point: a forward peak of the torso's front profile in the chest region (_front_peak),
    # not the region's lower edge, nor a belly standing further forward
    idx = prof.index_range(armpit - 0.12 * h, armpit - 0.01 * h)
    front = np.array([prof.central[i].points[:, 1].max() if prof.central[i] is not None else -np.inf
                      for i in idx])
    i_apex = idx[_front_peak(front, int(round(PEAK_BELOW * h / STEP)), int(round(CHEST_UPPER * h / STEP)))]
    m.bust_height = float(prof.ys[i_apex])

    # Waist: narrowest torso girth between the hips and the bust point; where the girth only
    # grows from the hips up to there (a belly: no natural waist) WAIST_SHARE of the way from the
    # crotch to the armpits, as ISO 8559-1 takes it half way between the ribs and the hip bone
    idx = prof.index_range(crotch + 0.1 * h, m.bust_height)
    g = np.array([prof.girth(i) for i in idx])
    k = int(np.nanargmin(g))
    if k >= len(idx) - 2:
        k = int(np.argmin(np.abs(prof.ys[idx] - (crotch + WAIST_SHARE * (armpit - crotch)))))
        m.notes.append("no natural waist (the torso narrows nowhere between the hips and the chest): the waist is "
                       f"taken {100 * WAIST_SHARE:.0f} % of the way from the crotch to the armpits")
    iw = idx[k]
    m.waist, m.waist_height = prof.girth(iw), float(prof.ys[iw])

    # Underbust: where the steep fall of the girth below the bust ends (knee of the profile:
    # the point farthest below the chord from the waist to the bust point).
    idx = np.arange(iw, i_apex + 1)
    low = m.bust_height - 0.03 * h
    if len(idx) >= 3:
        g = np.array([prof.girth(i) for i in idx])
        chord = g[0] + (g[-1] - g[0]) * (prof.ys[idx] - prof.ys[idx[0]]) / (prof.ys[idx[-1]] - prof.ys[idx[0]])
        iu = idx[int(np.nanargmax(chord - g))]
        m.underbust = prof.girth(iu)
        low = prof.ys[iu]
    else:
        m.notes.append("underbust not measured: the chest's front stands at the waist")
    # Bust (chest): largest girth from the underbust (at most 3 % of the height under the bust
    # point: not a belly's girth) to just below the armpits.
    idx = prof.index_range(min(max(low, m.bust_height - 0.03 * h), m.bust_height), armpit - 0.01 * h)
    g = np.array([prof.girth(i) for i in idx])
    if np.isfinite(g).any():
        m.bust = float(np.nanmax(g))

    # Hips: largest girth between the crotch and the waist; a little below the crotch the
    # tape goes around both legs (hull of the two leg pieces). The hip height is that of the
    # largest girth above the crotch (the seat): on men the thighs' hull under the crotch can be
    # the largest, and a hip line under the crotch puts the landmarks out of order
    best, best_y, seat, seat_y = -np.inf, np.nan, -np.inf, np.nan
    for i in prof.index_range(crotch - 0.03 * h, m.waist_height):
        if prof.ys[i] >= crotch:
            g = prof.girth(i)
            if np.isfinite(g) and g > seat:
                seat, seat_y = g, float(prof.ys[i])
        else:
            legs = _leg_pair(prof, prof.cuts[i])
            g = hull_perimeter(np.vstack([p.points for p in legs])) if legs else np.nan
        if np.isfinite(g) and g > best:
            best, best_y = g, float(prof.ys[i])
    if np.isfinite(best):
        m.hips, m.hip_height = best, (seat_y if np.isfinite(seat_y) else best_y)


BUST_PEAK_CUTS = 3  # a bust point stands at least as far forward as the cuts this far above and below
PEAK_BELOW = 0.04  # x height: ... and PEAK_RISE further forward than every cut this far below it
PEAK_RISE = 0.003  # m
CHEST_UPPER = 0.06  # x height under the armpits: where a flat chest's front is looked for
WAIST_SHARE = 0.58  # the waist's place between crotch and armpits where there is no narrowest girth


def _front_peak(front: np.ndarray, below: int, upper: int) -> int:
    """Index of the bust point in a front profile (cuts bottom to top): the highest cut at least
    as far forward as its BUST_PEAK_CUTS neighbours on each side, away from both ends, that
    stands PEAK_RISE forward of every cut up to `below` cuts under it (the chest, not a belly
    further down); without one, the most forward of the top `upper` cuts (a flat chest over a
    belly)."""
    k = BUST_PEAK_CUTS
    for j in range(len(front) - k - 1, k - 1, -1):
        if front[j] >= front[j - k:j + k + 1].max() and front[j] - front[max(0, j - below):j].min() >= PEAK_RISE:
            return j
    top = max(0, len(front) - upper)
    return top + int(np.argmax(front[top:]))


def _leg_pair(prof: _Profile, pieces: list[Piece]) -> list[Piece] | None:
    """The two legs: the longest piece left of the axis and the longest right of it."""
    left = [p for p in pieces if p.xmax < prof.ax]
    right = [p for p in pieces if p.xmin > prof.ax]
    if not left or not right:
        return None
    return [max(left, key=lambda p: p.length), max(right, key=lambda p: p.length)]


def _knee(prof: _Profile, h: float, crotch: float, m: Measurements) -> None:
    """Knee: the narrowest leg girth between the calf bulge and mid-thigh; fallback a standard
    proportion (0.285 of the height)."""
    idx = prof.index_range(0.12 * h, crotch - 0.05 * h)
    girth = []
    for i in idx:
        legs = _leg_pair(prof, prof.cuts[i])
        girth.append(np.mean([p.hull_perimeter for p in legs]) if legs else np.nan)
    girth = np.array(girth)
    calf_win = (prof.ys[idx] >= 0.15 * h) & (prof.ys[idx] <= 0.25 * h)
    if np.isfinite(girth).sum() < 5 or not np.isfinite(girth[calf_win]).any():
        m.knee_height = 0.285 * h
        m.notes.append("knee height from the standard proportion 0.285 x height")
        return
    i_calf = np.nonzero(calf_win)[0][int(np.nanargmax(np.where(calf_win, girth, -np.inf)[calf_win]))]
    sub = girth[i_calf:]
    m.knee_height = float(prof.ys[idx[i_calf + int(np.nanargmin(sub))]])


def _shoulders(v: np.ndarray, f: np.ndarray, prof: _Profile, h: float, armpit: float, m: Measurements):
    """Acromion points, a heuristic: laterally at the side walls of the torso just below the
    armpits (the torso wall runs up to the acromion; the bend of the shoulder-arm top profile
    sits on the deltoid, a few cm further out), vertically the top of the body's surface there
    (a cut by the plane x = wall, whatever the mesh's density)."""
    core = prof.central_piece(prof.cut(armpit - 0.005))
    if core is None:
        m.notes.append("shoulder points not found: no torso cut under the armpits")
        return None
    points = []
    for x in (core.xmin, core.xmax):
        top = _top_at_x(v, f, x, armpit)
        if top is None:
            m.notes.append("shoulder points not found: no surface above the armpits at the torso's sides")
            return None
        points.append(top)
    left, right = points
    m.shoulder_width = float(right[0] - left[0])
    m.shoulder_height = float(0.5 * (left[1] + right[1]))
    return left, right


def _top_at_x(v: np.ndarray, f: np.ndarray, x: float, y_min: float) -> np.ndarray | None:
    """(3,) highest point of the surface's cut by the plane x = x that is above y_min (None
    without one)."""
    pieces = slice_pieces(v[:, [1, 0, 2]], f, x)  # the cut's points come back as (y, z)
    pts = np.concatenate([p.points for p in pieces]) if pieces else np.zeros((0, 2))
    pts = pts[pts[:, 0] >= y_min]
    if len(pts) == 0:
        return None
    k = int(np.argmax(pts[:, 0]))
    return np.array([x, pts[k, 0], pts[k, 1]])


ARM_CUTS_MIN = 8  # an arm is measured from at least this many cuts across it


def _arms(v: np.ndarray, f: np.ndarray, prof: _Profile, armpit: float, acromion, m: Measurements) -> None:
    """Arm length: acromion -> elbow -> wrist, through the centres of the arm's cuts -- cuts
    across a hanging arm by the horizontal profile, or across an arm held out (T-pose) by
    planes x = const from the shoulder out. The wrist is the narrowest arm cut in the lower half
    of the arm, above the hand."""
    lengths = []
    for side, a in zip((-1.0, 1.0), acromion):
        cents, widths = _hanging_arm(prof, armpit, side)
        if len(cents) < ARM_CUTS_MIN:
            cents, widths = _held_out_arm(v, f, a, side)
        if len(cents) < ARM_CUTS_MIN:
            continue
        n = len(cents)
        lo, hi = int(0.45 * n), int(0.9 * n)
        iw = lo + int(np.argmin(widths[lo:hi]))
        wrist = cents[iw]
        # Elbow: the arm centre farthest from the straight acromion-wrist line (0 if straight).
        aw = wrist - a
        t = np.clip(((cents[:iw + 1] - a) @ aw) / max(aw @ aw, 1e-12), 0, 1)
        dist = np.linalg.norm(cents[:iw + 1] - (a + t[:, None] * aw), axis=1)
        elbow = cents[int(np.argmax(dist))]
        lengths.append(np.linalg.norm(elbow - a) + np.linalg.norm(wrist - elbow))
        m.arm_lines.append((np.asarray(a, dtype=np.float64).copy(), np.asarray(wrist, dtype=np.float64).copy()))
    if lengths:
        m.arm_length = float(np.mean(lengths))
    else:
        m.notes.append("arm length not measured: no arm found hanging below the armpits nor held out from the "
                       "shoulders")


def _arm_pieces(prof: _Profile, pieces: list[Piece], core: Piece | None, side: float) -> list[Piece]:
    """The pieces of a cut that belong to the arm on `side` (+1: +x): on that side of the body's
    axis (by their centre: an arm pressed into the torso overlaps it), neither the torso's piece
    nor, below the crotch, a leg's."""
    skip = [core] if core is not None else (_leg_pair(prof, pieces) or [])
    return [p for p in pieces if all(p is not q for q in skip) and side * (p.centroid[0] - prof.ax) > 0]


ARM_STEP = 0.06  # m: an arm's cut is within this of the one above it (horizontally)


def _arm_cuts(prof: _Profile, armpit: float, side: float) -> list[tuple[int, list[Piece]]]:
    """(cut index, the arm's pieces) from the armpit down to where the arm ends: each cut's
    arm pieces (_arm_pieces) near the arm's centre in the cut above (ARM_STEP: a leg's cut
    appearing beside a hanging hand at the crotch is not the arm)."""
    out, last = [], None
    for i in prof.index_range(0.0, armpit - 0.005)[::-1]:  # from the armpit downwards
        arm = _arm_pieces(prof, prof.cuts[i], prof.central[i], side)
        if last is not None:
            arm = [p for p in arm if np.linalg.norm(p.centroid - last) < ARM_STEP]
        if not arm:
            if out:
                break
            continue
        last = _centre(arm)
        out.append((i, arm))
    return out


def _centre(pieces: list[Piece]) -> np.ndarray:
    """(2,) the length-weighted centre of the pieces' centres."""
    w = np.array([p.length for p in pieces])
    return (np.array([p.centroid for p in pieces]) * w[:, None]).sum(axis=0) / w.sum()


def _hanging_arm(prof: _Profile, armpit: float, side: float) -> tuple[np.ndarray, np.ndarray]:
    """(centres (K, 3), hull perimeters (K,)) of the arm's horizontal cuts from the armpit down
    to where the arm ends."""
    cents, widths = [], []
    for i, arm in _arm_cuts(prof, armpit, side):
        c = _centre(arm)
        cents.append([c[0], prof.ys[i], c[1]])
        widths.append(hull_perimeter(np.vstack([p.points for p in arm])))
    return np.array(cents).reshape(-1, 3), np.array(widths)


def _hand_gap(prof: _Profile, armpit: float, waist: float) -> float:
    """The smallest distance between the points of an arm's cut below the waist and those of
    the other pieces of the cut (torso, legs), on either side (measure's hand_gap)."""
    from scipy.spatial import cKDTree

    gap = np.inf
    for side in (-1.0, 1.0):
        for i, arm in _arm_cuts(prof, armpit, side):
            rest = [p for p in prof.cuts[i] if all(p is not q for q in arm)]
            if prof.ys[i] > waist or not rest:
                continue
            d, _ = cKDTree(np.vstack([p.points for p in rest])).query(np.vstack([p.points for p in arm]))
            gap = min(gap, float(d.min()))
    return gap if np.isfinite(gap) else float("nan")


def _held_out_arm(v: np.ndarray, f: np.ndarray, acromion: np.ndarray, side: float) -> tuple[np.ndarray, np.ndarray]:
    """As _hanging_arm for an arm held out sideways: cuts by the planes x = const every STEP from
    the acromion outwards, the pieces there above the acromion's height less 25 cm."""
    xs = acromion[0] + side * np.arange(STEP, 1.2, STEP)
    order = np.argsort(xs)
    cuts: list = [None] * len(xs)
    for k, pieces in zip(order, slice_stack(v[:, [1, 0, 2]], f, xs[order])):  # points come back as (y, z)
        cuts[k] = pieces
    cents, widths = [], []
    for x, pieces in zip(xs, cuts):
        arm = [p for p in pieces if p.centroid[0] > acromion[1] - 0.25]
        if not arm:
            if cents:
                break
            continue
        c = _centre(arm)
        cents.append([x, c[0], c[1]])
        widths.append(hull_perimeter(np.vstack([p.points for p in arm])))
    return np.array(cents).reshape(-1, 3), np.array(widths)


