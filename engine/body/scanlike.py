"""Scan-like versions of a body, for tests and the body benchmark (scripts/bench_bodies.py):
what a scanner or another body model hands over instead of our normalised mesh.

    v, f = scan_like(body, "mm")                 # vertices and faces as the file would hold them
    write_scan(path, body, "holes")              # ... written as a mesh file

A variant is one of VARIANTS: units (mm, inches), axes (Z up; facing -Z or +X; off the
origin), mesh density (decimated to 10k triangles, subdivided to 500k), damage (holes at the
crown, the soles and under the arms; 1 mm noise; a floor plate under the feet) and arm poses
(lowered to 20 degrees from the body, lowered until the hands touch the thighs, T-pose). The
poses need a skeleton: a body without one gets the default skeleton fitted to it
(engine.body.fit), as a scan that walks does. Everything is deterministic (fixed seeds).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.body.types import SEGMENT_ID, Body
from engine.errors import InputError

INCH = 0.0254
VARIANTS = {
    "mm": "scaled to millimetres",
    "inches": "scaled to inches",
    "z-up": "Z up (Y forward)",
    "face-z": "facing -Z",
    "face+x": "facing +X",
    "off-origin": "shifted 3 m off the origin",
    "decimated": "decimated to 10,000 triangles",
    "subdivided": "subdivided to ~500,000 triangles",
    "holes": "holes at the crown, the soles and under the arms",
    "noise": "1 mm noise on every vertex",
    "floor": "standing on a 1 m floor plate",
    "arms20": "arms lowered to 20 degrees from the body",
    "arms-thighs": "arms lowered until the hands touch the thighs",
    "t-pose": "T-pose (arms straight out)",
}
POSES = ("arms20", "arms-thighs", "t-pose")
DECIMATED = 10_000
SUBDIVIDED = 500_000
NOISE = 0.001  # m, standard deviation per coordinate


def scan_like(body: Body, variant: str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (N, 3) float64, faces (F, 3) int64) of `body` made scan-like (module doc), in
    the coordinates a file would hold (mm for "mm", Z up for "z-up", ...)."""
    if variant not in VARIANTS:
        raise InputError(f"unknown scan variant '{variant}': choose one of {', '.join(VARIANTS)}")
    v, f = np.asarray(body.vertices, np.float64), np.asarray(body.faces, np.int64)
    if variant in POSES:
        return posed_arms(body, variant), f
    simple = {"mm": lambda: (v * 1000.0, f), "inches": lambda: (v / INCH, f),
              "z-up": lambda: (v[:, [0, 2, 1]] * np.array([-1.0, 1.0, 1.0]), f),  # (x, y, z) -> (-x, z, y)
              "face-z": lambda: (v * np.array([-1.0, 1.0, -1.0]), f),
              "face+x": lambda: (v[:, [2, 1, 0]] * np.array([1.0, 1.0, -1.0]), f),
              "off-origin": lambda: (v + np.array([3.1, 0.7, -2.4]), f),
              "decimated": lambda: _decimated(v, f, DECIMATED),
              "subdivided": lambda: _subdivided(v, f, SUBDIVIDED),
              "holes": lambda: (v, _holed(body)),
              "noise": lambda: (v + np.random.default_rng(48).normal(0.0, NOISE, v.shape), f),
              "floor": lambda: _with_floor(v, f)}
    return simple[variant]()


def write_scan(path, body: Body, variant: str) -> Path:
    """scan_like(body, variant) written to `path` (any format trimesh writes: .obj .ply .stl)."""
    import trimesh

    v, f = scan_like(body, variant)
    path = Path(path)
    trimesh.Trimesh(v, f, process=False).export(path)
    return path


# --------------------------------------------------------------------------- mesh density


def _decimated(v: np.ndarray, f: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    import fast_simplification

    v2, f2 = fast_simplification.simplify(v.astype(np.float32), f.astype(np.int32),
                                          target_reduction=1.0 - target / len(f))
    return np.asarray(v2, np.float64), np.asarray(f2, np.int64)


def _subdivided(v: np.ndarray, f: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    """Edges split until every one is shorter than the edge of an equilateral triangle of the
    surface's area / target (trimesh.remesh.subdivide_to_size): about `target` triangles, the
    same surface."""
    import trimesh

    area = float(trimesh.Trimesh(v, f, process=False).area)
    edge = float(np.sqrt(4.0 * area / (np.sqrt(3.0) * target)))
    v2, f2 = trimesh.remesh.subdivide_to_size(v, f, max_edge=1.5 * edge, max_iter=12)
    return np.asarray(v2, np.float64), np.asarray(f2, np.int64)


# --------------------------------------------------------------------------- damage

CROWN = 0.025  # m below the top of the head: the crown's cap is cut away
SOLE = 0.008  # m above the floor: downward faces of the soles are cut away
UNDERARM = 0.035  # m around each armpit point


def _holed(body: Body) -> np.ndarray:
    """The faces without a cap at the crown, the soles' downward faces and a patch under each
    arm (where the torso meets the arm, found by engine.body.measure)."""
    from engine.body.measure import measure

    v, f = body.vertices, np.asarray(body.faces, np.int64)
    c = v[f].mean(axis=1)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-20)
    floor, top = v[:, 1].min(), v[:, 1].max()
    cut = (c[:, 1] > top - CROWN) | ((c[:, 1] < floor + SOLE) & (n[:, 1] < -0.5))
    m = measure(body)
    if np.isfinite(m.armpit_height):
        from engine.body.measure import slice_pieces

        y = m.armpit_height - 0.01
        pieces = slice_pieces(v, body.faces, y)
        core = max(pieces, key=lambda p: p.length) if pieces else None
        if core is not None:
            zc = float(core.centroid[1])
            for x in (core.xmin, core.xmax):
                cut |= np.linalg.norm(c - np.array([x, y, zc]), axis=1) < UNDERARM
    return f[~cut]


def _with_floor(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A 1 m x 1 m x 1 cm plate (a separate box) with its top at the soles."""
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 0.01, 1.0))
    lo = v.min(axis=0)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    bv = np.asarray(box.vertices) + np.array([centre[0], lo[1] - 0.005, centre[2]])
    return np.concatenate([v, bv]), np.concatenate([f, np.asarray(box.faces, np.int64) + len(v)])


# --------------------------------------------------------------------------- arm poses

ARMS_LOWERED = 20.0  # degrees between the upper arm and the vertical (arms20)
TOUCH = 0.005  # m: the hands touch the thighs when this close (arms-thighs)


def posed_arms(body: Body, variant: str) -> np.ndarray:
    """The body's vertices with its arms posed (POSES): both arm bones turned in the body's
    frontal plane to an angle from the vertical -- ARMS_LOWERED, 90 (T-pose), or the largest
    angle, in whole degrees, at which a hand comes within TOUCH of a thigh; the forearm in line
    with the upper arm in the frontal plane (it keeps its forward bend)."""
    from engine.body.fit import fit_rig

    rigged = body if body.rig is not None else fit_rig(body, "male" if _male(body) else "female")
    if variant == "arms20":
        return _arms_at(rigged, ARMS_LOWERED)
    if variant == "t-pose":
        return _arms_at(rigged, 90.0)
    hand = _hand_vertices(rigged)
    leg = np.isin(rigged.segments, [SEGMENT_ID["left_leg"], SEGMENT_ID["right_leg"]])
    from scipy.spatial import cKDTree

    for deg in np.arange(ARMS_LOWERED, -0.5, -1.0):
        v = _arms_at(rigged, float(deg))
        d, _ = cKDTree(v[leg]).query(v[hand])
        if d.min() <= TOUCH:
            return v
    return v


def _male(body: Body) -> bool:
    from engine.body.measure import measure
    from engine.body.sex import body_sex

    return body_sex(body, measure(body)) == "male"


def _hand_vertices(rigged: Body) -> np.ndarray:
    """Vertices weighted mostly to the wrist and the fingers."""
    rig = rigged.rig
    hand = np.array([n.startswith(("wrist", "finger", "metacarpal")) for n in rig.joint_names])
    return np.nonzero((rig.skin_weights * hand[rig.skin_indices]).sum(axis=1) > 0.5)[0]


def _frontal_angle(d: np.ndarray) -> float:
    """Degrees of direction d from straight down, in the frontal (x, y) plane."""
    return float(np.degrees(np.arctan2(abs(d[0]), -d[1])))


def _arms_at(rigged: Body, degrees: float) -> np.ndarray:
    from engine.body.motion import _rot, pose_joints
    from engine.body.rig import skin

    rig = rigged.rig
    idx = {n: i for i, n in enumerate(rig.joint_names)}
    rest = rig.rest_transforms
    deltas = {}
    for side, sign in (("L", 1.0), ("R", -1.0)):
        sh, el, wr = (rest[idx[f"{n}.{side}"], :3, 3] for n in ("upperarm01", "lowerarm01", "wrist"))
        up = _rot("z", sign * (degrees - _frontal_angle(el - sh)))
        fore = up @ (wr - el)
        deltas[f"upperarm01.{side}"] = up
        # (a child's delta is in the rest frame, before its parent's turn: conjugated)
        deltas[f"lowerarm01.{side}"] = up.T @ _rot("z", sign * (degrees - _frontal_angle(fore))) @ up
    return skin(rigged.vertices, rig, pose_joints(rig, deltas))
