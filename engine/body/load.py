"""Load a body scan (OBJ, PLY, STL, OFF, GLB/glTF) and normalise it to the world frame of
DESIGN.md: metres, Y up, facing +Z, feet on y = 0, centred on x = z = 0 (bounding-box centre).

Units come from a plausible human height (metres, dm, cm, mm or inches; an adult's where two fit); the up axis from the shape (standing human: the long
axis; the end with the flat soles is down); the front from the feet (toes point forward) and the
face; a body standing turned about the vertical (10-45 degrees off the file's axes) is turned back
square, its depth the horizontal direction of least spread. Messy scans are repaired
(duplicate vertices merged, degenerate faces and tiny floating bits dropped, holes closed, a
floor plate under the feet dropped) and every decision is written to Body.notes.

Holes: scanners leave the crown, the soles, armpits and the crotch open, and drop scattered
triangles. A horizontal cut through a hole is not a closed loop, so measurements read nonsense
(measured on the sample scan with such holes cut in, tests/test_body_load.py: bust 128.5 cm
instead of 97.5, waist 56.9 at 1.20 m, shoulders 8 cm wide) and the collision maps see into
the body. Every hole is closed with MeshFix (pymeshfix: boundary loops triangulated and
refined, the scan's own vertices and faces kept); the note says how many and how large. A hole
that spans the gap between an arm and the torso is bridged (the armpits are then found low).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from engine.body.types import Body
from engine.errors import InputError, parser
from engine.settings import current

SUPPORTED = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}
UNITS = ((1.0, "metres"), (0.1, "decimetres"), (0.01, "centimetres"), (0.001, "millimetres"), (0.0254, "inches"))
HUMAN_HEIGHT = (0.5, 2.5)  # m; the metric scales give non-overlapping raw ranges ...
ADULT_HEIGHT = (1.3, 2.3)  # m: ... inches overlap centimetres (70 units: 1.78 m or 0.70 m): the adult
# reading wins, and inches are taken for adults only
MAX_PARTS = 512  # mesh parts placed in a scene file (one small part placed thousands of times took minutes)
TINY_PIECE = 0.01  # drop components under this fraction of the total surface area


@parser("a mesh")
def load_body_file(path, up: str | None = None, front: str | None = None,
                   max_triangles: int | None = None, fill_holes: bool = True) -> Body:
    """Read a mesh file and return a normalised Body (see module doc).

    up / front: "+x" "-x" "+y" "-y" "+z" "-z" in the file's coordinates, overriding detection.
    max_triangles: refuse bigger meshes; None -> the TRYON_MAX_TRIANGLES setting (engine.settings).
    fill_holes: close holes (module doc); False keeps the file's vertices one for one (the first
    frame of an animation, whose other frames move the same vertices).
    Raises InputError (one line) for anything that cannot be used.
    """
    path = Path(path)
    up_ax = _parse_axis(up, "--up")
    front_ax = _parse_axis(front, "--front")
    if up_ax and front_ax and up_ax[0] == front_ax[0]:
        raise InputError(f"--up {up} and --front {front} are the same axis: give two perpendicular axes, e.g. --up +y --front +z")
    cap = _triangle_cap(max_triangles)
    vertices, faces = _read(path)
    if len(faces) > cap:
        raise InputError(f"{path.name}: {len(faces):,} triangles, more than the limit of {cap:,}: "
                         "decimate the scan or raise TRYON_MAX_TRIANGLES")
    notes: list[str] = []
    vertices, faces = _clean(vertices, faces, path.name, notes)
    filled = None
    if fill_holes:
        vertices, faces, filled = _fill_holes(vertices, faces, path.name, notes)

    # Axes: up = long axis of a standing human, its sign from the shape unless given.
    if up_ax is None:
        up_ax = _detect_up(vertices, faces, front_ax, notes)
    extent = np.ptp(vertices[:, up_ax[0]])
    scale, unit = _units(extent, path.name)
    if front_ax is None:
        front_ax = _detect_front(vertices, faces, up_ax, notes)
    rot = _rotation(up_ax, front_ax)
    world = (vertices @ rot.T) * scale
    world, faces = _drop_floor(world, faces, notes)
    turn = _facing_turn(world, faces)
    if turn is not None:  # (a scan of someone standing turned on the turntable: face +Z square)
        c, s_ = np.cos(-turn), np.sin(-turn)  # (about +Y by -turn: the depth axis onto +Z)
        yaw = np.array([[c, 0.0, s_], [0.0, 1.0, 0.0], [-s_, 0.0, c]])
        world = world @ yaw.T
        rot = yaw @ rot
        notes.append(f"turned {np.degrees(-turn):+.0f} degrees about the vertical: the body stood turned "
                     f"{abs(np.degrees(turn)):.0f} degrees from the file's {_axis_name(front_ax)} axis "
                     "(its shoulders' line square to the front now)")
    # Feet on y = 0, centred on x = z = 0 (bounding-box centre).
    lo, hi = world.min(axis=0), world.max(axis=0)
    shift = np.array([-(lo[0] + hi[0]) / 2, -lo[1], -(lo[2] + hi[2]) / 2])
    world += shift
    to_world = np.eye(4)
    to_world[:3, :3] = scale * rot
    to_world[:3, 3] = shift

    faces = _orient(world, faces, notes)
    notes.insert(0, f"units: {unit} (height {extent:.4g} in file units -> {world[:, 1].max():.3f} m)")
    notes.insert(1, f"axes: up {_axis_name(up_ax)}, front {_axis_name(front_ax)} (file coordinates)")
    left = _report_holes(world, faces, notes)
    if filled is not None:
        found, largest = filled
        notes.insert(2, f"closed {found - left} of {found} hole(s) in the surface with MeshFix (largest "
                        f"{largest * scale * 100:.1f} cm around)")
    return Body(vertices=world, faces=faces.astype(np.int32), name=path.stem, notes=notes,
                to_world=to_world)


# --------------------------------------------------------------------------- input checks


def _parse_axis(s: str | None, flag: str):
    if s is None:
        return None
    key = s.strip().lower()
    if key in ("x", "y", "z"):
        key = "+" + key
    if key not in AXES:
        raise InputError(f"{flag} '{s}' is not an axis: use one of +x -x +y -y +z -z")
    return AXES[key]


def _axis_name(ax) -> str:
    return ("+" if ax[1] > 0 else "-") + "xyz"[ax[0]]


def _triangle_cap(max_triangles: int | None) -> int:
    if max_triangles is not None:
        return int(max_triangles)
    return current().max_triangles


def _read(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) float64 vertices and (F, 3) int64 triangles of all meshes in the file, each with
    its scene transform applied."""
    ext = path.suffix.lower()
    if ext not in SUPPORTED:
        raise InputError(f"{path.name}: unsupported file type '{ext or 'none'}': give one of {' '.join(SUPPORTED)}")
    if not path.is_file():
        raise InputError(f"body file not found: {path}")
    if path.stat().st_size == 0:
        raise InputError(f"{path.name} is empty: give a mesh file with triangles")
    import trimesh

    try:
        scene = trimesh.load_scene(str(path), file_type=ext[1:], process=False)
        if len(scene.graph.nodes_geometry) > MAX_PARTS:  # checked before the copies are made
            raise InputError(f"{path.name} places more than {MAX_PARTS} mesh parts: a body is one mesh (or a few); "
                             "merge them on export")
        geoms = scene.dump(concatenate=False)
    except Exception as e:  # trimesh raises anything on garbage; the user needs one line
        msg = str(e).splitlines()[0][:120] if str(e) else type(e).__name__
        raise InputError(f"{path.name} could not be read as {ext[1:].upper()} ({msg}): check that the file is a valid mesh") from None
    verts, faces, offset, n_points = [], [], 0, 0
    for g in geoms:
        v = np.asarray(getattr(g, "vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
        f = np.asarray(getattr(g, "faces", np.zeros((0, 3))), dtype=np.int64)
        if f.size == 0 or f.ndim != 2 or f.shape[1] != 3:
            n_points += len(v)
            continue
        if f.min() < 0 or f.max() >= len(v):
            raise InputError(f"{path.name}: faces refer to vertices that do not exist: the file is corrupt")
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)
    if not faces:
        if n_points:
            raise InputError(f"{path.name} has only points ({n_points:,}), no faces: give a triangle mesh "
                             "(mesh the point cloud first)")
        raise InputError(f"{path.name} contains no triangles: check that it is a valid {ext[1:].upper()} mesh file")
    return np.concatenate(verts), np.concatenate(faces)


def _units(extent: float, name: str) -> tuple[float, str]:
    fits = [(scale, unit) for scale, unit in UNITS if HUMAN_HEIGHT[0] <= extent * scale <= HUMAN_HEIGHT[1]]
    adult = [(scale, unit) for scale, unit in fits if ADULT_HEIGHT[0] <= extent * scale <= ADULT_HEIGHT[1]]
    fits = [(scale, unit) for scale, unit in fits if unit != "inches"]  # inches only for an adult
    if adult or fits:
        return (adult or fits)[0]
    raise InputError(f"{name} is not human-sized: {extent:.4g} units tall fits no unit (m, dm, cm, mm, inches) "
                     f"for a {HUMAN_HEIGHT[0]}-{HUMAN_HEIGHT[1]} m person: check the file or its scale")


# --------------------------------------------------------------------------- repairs


def _clean(v: np.ndarray, f: np.ndarray, name: str, notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Drop unused vertices, refuse non-finite ones, merge duplicates, drop degenerate faces and
    tiny disconnected pieces. Keeps the vertex order of the file where nothing changes."""
    v, f = _compact(v, f)
    if not np.isfinite(v).all():
        raise InputError(f"{name} has non-finite (NaN or infinite) vertex coordinates: repair or re-export the scan")
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    if diag <= 0:
        raise InputError(f"{name}: all vertices are at one point: give a real mesh")
    # Merge duplicates: vertices closer than 1e-10 of the size (unit-independent; only true
    # duplicates, e.g. STL corners or UV seams; near-coincident lips stay apart). A k-d tree
    # pair search, not a rounding grid, so that scaled/rotated copies merge identically.
    pairs = cKDTree(v).query_pairs(diag * 1e-10, output_type="ndarray")
    if len(pairs):
        n = len(v)
        _, label = connected_components(
            coo_matrix((np.ones(len(pairs), np.int8), (pairs[:, 0], pairs[:, 1])), shape=(n, n)), directed=False)
        first = np.full(label.max() + 1, n)
        np.minimum.at(first, label, np.arange(n))  # each group keeps its first vertex
        keep = first[label] == np.arange(n)
        new_index = np.cumsum(keep) - 1
        notes.append(f"merged {n - int(keep.sum()):,} duplicate vertices")
        f = new_index[first[label]][f]
        v = v[keep]
    # Degenerate faces: repeated corners or (near) zero area.
    area = _areas(v, f)
    bad = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2]) | (area <= 1e-14 * diag * diag)
    if bad.any():
        notes.append(f"removed {int(bad.sum()):,} degenerate faces")
        f, area = f[~bad], area[~bad]
    if len(f) == 0:
        raise InputError(f"{name}: every face is degenerate (zero area): give a real mesh")
    # Tiny disconnected bits (floating scan noise); a body in several real pieces is kept.
    ncomp, label = _components(len(v), f)
    if ncomp > 1:
        comp_area = np.bincount(label[f[:, 0]], area, ncomp)
        tiny = comp_area < TINY_PIECE * comp_area.sum()
        if tiny.any():
            keep = ~tiny[label[f[:, 0]]]
            pct = 100.0 * comp_area[tiny].sum() / comp_area.sum()
            notes.append(f"dropped {int(tiny.sum())} small disconnected piece(s) ({pct:.2g} % of the surface)")
            f = f[keep]
        kept = int((~tiny).sum())
        if kept > 1:
            notes.append(f"the body is in {kept} separate pieces (kept all)")
    return _compact(v, f)


def _fill_holes(v: np.ndarray, f: np.ndarray, name: str, notes: list[str]):
    """Close every hole of the surface with MeshFix (module doc). Returns (v, f, None) for a
    mesh without holes, else (v, f, (holes found, largest loop in file units)).
    The filled mesh is cleaned again (MeshFix splits vertices where the surface is not a
    manifold; those duplicates are merged back, silently: they are not the file's)."""
    loops = _hole_loops(v, f)
    if len(loops) == 0:
        return v, f, None
    from pymeshfix import PyTMesh

    tm = PyTMesh()
    tm.set_quiet(True)
    tm.load_array(np.ascontiguousarray(v, dtype=np.float64), np.ascontiguousarray(f, dtype=np.int32))
    tm.fill_small_boundaries(nbe=0, refine=True)
    v2, f2 = tm.return_arrays()
    v2, f2 = np.asarray(v2, np.float64), np.asarray(f2, np.int64)
    if len(f2) < len(f) or not np.isfinite(v2).all():  # never trade the scan for a worse mesh
        notes.append(f"{len(loops)} hole(s) could not be closed (MeshFix failed on this mesh)")
        return v, f, None
    v2, f2 = _clean(v2, f2, name, [])
    return _faired(v, v2, f2), f2, (len(loops), float(loops.max()))


def _faired(v0: np.ndarray, v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The vertices MeshFix added (those not among the scan's own, v0) moved to where the
    surface bends on smoothly from the scan round them: bi-Laplacian (thin-plate) fairing with
    the scan's vertices fixed, L^2 x = 0 on the new ones (uniform weights). MeshFix's patches are
    flat, and a flat crown takes centimetres off the height."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    d, _ = cKDTree(v0).query(v)
    new = d > 1e-9 * max(float(np.ptp(v0, axis=0).max()), 1e-12)
    if not new.any() or new.all():
        return v
    n = len(v)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    adj = ((adj + adj.T) > 0).astype(np.float64)
    deg = np.asarray(adj.sum(axis=1)).ravel()
    lap = sp.diags(1.0 / np.maximum(deg, 1.0)) @ adj - sp.eye(n)
    bi = (lap @ lap).tocsr()
    a = bi[new][:, new].tocsc()
    b = -(bi[new][:, ~new] @ v[~new])
    out = v.copy()
    out[new] = spsolve(a, b).reshape(-1, 3)
    if not np.isfinite(out).all():
        return v
    return out


FLOOR_THICK = 0.03  # m: a separate piece at most this tall, lying under the feet ...
FLOOR_WIDE = 0.2  # m: ... and at least this wide is the scanner's floor or turntable, not the body


def _drop_floor(v: np.ndarray, f: np.ndarray, notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Drop a floor plate the scan was captured standing on (world frame, metres): a separate
    piece, thin and wide, whose top is no higher than 2 cm above the lowest point of the rest.
    Kept, it adds its thickness to every height and stands in the collision maps and the walk."""
    ncomp, label = _components(len(v), f)  # (every vertex is used: the mesh is compacted)
    if ncomp < 2:
        return v, f
    flabel = label[f[:, 0]]
    drop = np.zeros(ncomp, bool)
    for c in range(ncomp):
        mine = label == c
        lo, hi = v[mine].min(axis=0), v[mine].max(axis=0)
        if (hi[1] - lo[1] <= FLOOR_THICK and np.hypot(hi[0] - lo[0], hi[2] - lo[2]) >= FLOOR_WIDE
                and hi[1] <= v[~mine, 1].min() + 0.02):
            drop[c] = True
            notes.append(f"dropped the floor plate under the feet ({(hi[0] - lo[0]) * 100:.0f} x "
                         f"{(hi[2] - lo[2]) * 100:.0f} cm, {(hi[1] - lo[1]) * 100:.1f} cm thick)")
    if not drop.any() or drop.all():
        return v, f
    notes[:] = [n for n in notes if not n.startswith("the body is in")]
    if ncomp - int(drop.sum()) > 1:
        notes.append(f"the body is in {ncomp - int(drop.sum())} separate pieces (kept all)")
    return _compact(v, f[~drop[flabel]])


def _compact(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    used = np.zeros(len(v), bool)
    used[f.reshape(-1)] = True
    if used.all():
        return v, f
    new = np.cumsum(used) - 1
    return v[used], new[f]


def _areas(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    t = v[f]
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)


def _components(n: int, f: np.ndarray) -> tuple[int, np.ndarray]:
    rows = np.concatenate([f[:, 0], f[:, 1]])
    cols = np.concatenate([f[:, 1], f[:, 2]])
    g = coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(n, n))
    return connected_components(g, directed=False)


def _orient(v: np.ndarray, f: np.ndarray, notes: list[str]) -> np.ndarray:
    """Flip the winding if the normals point inwards (negative enclosed volume)."""
    t = v[f]
    vol = np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0
    if vol < 0:
        notes.append("flipped the face winding (normals pointed inwards)")
        return f[:, ::-1].copy()
    return f


def _hole_loops(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Lengths of the boundary loops (chains of edges used by one face), in v's units."""
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1).astype(np.int64)
    key, cnt = np.unique(e[:, 0] * len(v) + e[:, 1], return_counts=True)  # 1-D: fast on 2M faces
    once = key[cnt == 1]
    if len(once) == 0:
        return np.zeros(0)
    b = np.stack([once // len(v), once % len(v)], axis=1)
    ncomp, label = connected_components(
        coo_matrix((np.ones(len(b), np.int8), (b[:, 0], b[:, 1])), shape=(len(v), len(v))), directed=False)
    length = np.linalg.norm(v[b[:, 0]] - v[b[:, 1]], axis=1)
    loop_len = np.bincount(label[b[:, 0]], length, ncomp)
    return loop_len[loop_len > 0]


def _report_holes(v: np.ndarray, f: np.ndarray, notes: list[str]) -> int:
    """Note the holes left (boundary loops) and the largest one's length; returns their count."""
    loops = _hole_loops(v, f)
    if len(loops):
        notes.append(f"{len(loops)} hole(s) in the surface, largest {loops.max() * 100:.1f} cm around "
                     "(measurements across a hole are approximate)")
    return len(loops)


# --------------------------------------------------------------------------- axes


def _area_stats(v: np.ndarray, f: np.ndarray):
    c = v[f].mean(axis=1)
    a = _areas(v, f)
    return c, a / a.sum()


def _detect_up(v: np.ndarray, f: np.ndarray, front_ax, notes: list[str]):
    """Up axis: the axis along which the surface is spread most (area-weighted std; a standing
    body's height beats even a T-pose arm span, whose area is mostly near the middle). Sign:
    the end with the flat soles (most area within 4 % of the end) is down; if both ends look
    alike, the end whose cut is in two pieces (legs) rather than one (head)."""
    c, w = _area_stats(v, f)
    mean = (c * w[:, None]).sum(axis=0)
    std = np.sqrt(((c - mean) ** 2 * w[:, None]).sum(axis=0))
    order = np.argsort(std)[::-1]
    axis = int(order[0]) if front_ax is None or order[0] != front_ax[0] else int(order[1])
    if std[order[1]] > 0.8 * std[axis] and (front_ax is None or order[1] != front_ax[0]):
        notes.append(f"up axis {'xyz'[axis]} guessed with low confidence (body about as wide as tall); "
                     "pass --up if the result looks wrong")
    x = c[:, axis]
    lo, hi = x.min(), x.max()
    band = 0.04 * (hi - lo)
    a_lo, a_hi = w[x < lo + band].sum(), w[x > hi - band].sum()
    ratio = (a_lo + 1e-12) / (a_hi + 1e-12)
    if ratio > 1.5:
        return (axis, 1.0)
    if ratio < 1 / 1.5:
        return (axis, -1.0)
    # Weak: count pieces of cuts at 15 % from each end (legs: two, head/neck: one).
    from engine.body.measure import slice_pieces

    perm = [i for i in range(3) if i != axis]
    vv = v[:, [perm[0], axis, perm[1]]]
    n_lo = len([p for p in slice_pieces(vv, f, lo + 0.15 * (hi - lo)) if p.length > 0.02 * (hi - lo)])
    n_hi = len([p for p in slice_pieces(vv, f, hi - 0.15 * (hi - lo)) if p.length > 0.02 * (hi - lo)])
    sign = 1.0 if n_lo >= n_hi else -1.0
    if n_lo == n_hi:
        sign = 1.0 if ratio >= 1 else -1.0
    notes.append(f"up direction {'+' if sign > 0 else '-'}{'xyz'[axis]} guessed with low confidence; "
                 "pass --up if the result looks wrong")
    return (axis, sign)


def _detect_front(v: np.ndarray, f: np.ndarray, up_ax, notes: list[str]):
    """Front: the depth axis is the horizontal axis with the smaller area-weighted spread; its
    sign from the feet (toes reach further forward of the shins than the heels reach back) and,
    when the feet say little, from the face (nose and chin stick out in front of the neck)."""
    c, w = _area_stats(v, f)
    up, s = up_ax
    h = c[:, up] * s
    lo, hi = h.min(), h.max()
    height = hi - lo
    horiz = [i for i in range(3) if i != up]
    mean = (c * w[:, None]).sum(axis=0)
    std = np.sqrt(((c - mean) ** 2 * w[:, None]).sum(axis=0))
    depth = horiz[int(np.argmin(std[horiz]))]
    d = c[:, depth]
    conf_axis = std[horiz].max() > 1.25 * std[horiz].min()

    def span(sel):
        return (d[sel].min(), d[sel].max()) if sel.any() else (np.nan, np.nan)

    # Feet: forward reach of the soles beyond the shin cut, minus the backward reach (heel).
    foot = h < lo + 0.03 * height
    shin = (h > lo + 0.08 * height) & (h < lo + 0.12 * height)
    (f0, f1), (s0, s1) = span(foot), span(shin)
    feet_cue = ((f1 - s1) - (s0 - f0)) / height if np.isfinite([f0, s0]).all() else 0.0
    # Face: the head (top 6-12 %) reaches further forward of the neck than back.
    head = (h > hi - 0.12 * height) & (h < hi - 0.06 * height)
    neck = (h > hi - 0.16 * height) & (h < hi - 0.13 * height)
    (h0, h1), (n0, n1) = span(head), span(neck)
    face_cue = ((h1 - n1) - (n0 - h0)) / height if np.isfinite([h0, n0]).all() else 0.0
    cue = feet_cue if abs(feet_cue) > 0.03 else feet_cue + face_cue
    sign = 1.0 if cue >= 0 else -1.0
    if abs(cue) < 0.02 or not conf_axis:
        notes.append(f"front {'+' if sign > 0 else '-'}{'xyz'[depth]} guessed with low confidence "
                     "(no clear feet or face cue); pass --front if the result looks wrong")
    return (depth, sign)


TURN_MIN = np.radians(10.0)  # a body turned less than this about the vertical is left as it stands (an
# arm swung forward or a stride still skews the trunk's spread by a few degrees)
TURN_WIDER = 1.3  # ... and turned only where its trunk's side-to-side spread is this x its front-to-back one
TURN_BAND = (0.5, 0.75)  # the trunk: this share of the height up from the soles (hips to shoulders) ...
TURN_RADIUS = 0.3  # m: ... within this of its middle (the shoulders and upper arms, not the hands)


def _facing_turn(world: np.ndarray, f: np.ndarray) -> float | None:
    """How far a body stands turned about the vertical from the front axis (radians: its depth
    axis's angle from +Z toward +X; load_body_file turns it back): the horizontal direction of
    least area-weighted spread of its trunk (TURN_BAND, TURN_RADIUS: hips to shoulders, not the
    legs or hands, which a stride or a swing turns) is its depth. None where it is within
    TURN_MIN already or the spread gives no clear direction (TURN_WIDER). Measured on the sample
    scan turned 30 degrees: the shirt placed square to the file's axis stalled with a sleeve
    across the chest."""
    c, w = _area_stats(world, f)
    # the trunk, hips to shoulders: a stride, or a hand swung forward or held out, would skew it
    lo, hi = c[:, 1].min(), c[:, 1].max()
    band = (c[:, 1] > lo + TURN_BAND[0] * (hi - lo)) & (c[:, 1] < lo + TURN_BAND[1] * (hi - lo))
    if not band.any() or w[band].sum() <= 0:
        return None
    mid = (c[band][:, [0, 2]] * w[band, None]).sum(axis=0) / w[band].sum()
    band &= np.linalg.norm(c[:, [0, 2]] - mid, axis=1) < TURN_RADIUS
    if not band.any() or w[band].sum() <= 0:
        return None
    xz, wb = c[band][:, [0, 2]], w[band] / w[band].sum()
    xz = xz - (xz * wb[:, None]).sum(axis=0)
    cov = (xz * wb[:, None]).T @ xz
    val, vec = np.linalg.eigh(cov)  # ascending: vec[:, 0] the least spread (front to back)
    if not (val[0] > 0 and val[1] >= TURN_WIDER ** 2 * val[0]):
        return None
    dx, dz = vec[:, 0]
    if dz < 0:
        dx, dz = -dx, -dz  # (the front stays the side the file's front axis named)
    turn = float(np.arctan2(dx, dz))  # the depth axis's angle from +Z, toward +X
    return turn if TURN_MIN <= abs(turn) <= np.pi / 4 else None


def _rotation(up_ax, front_ax) -> np.ndarray:
    """Proper rotation (rows: world x, y, z in file coordinates) taking up -> +Y, front -> +Z."""
    if up_ax[0] == front_ax[0]:
        raise InputError("up and front are the same axis: pass perpendicular --up and --front")
    u = np.zeros(3)
    u[up_ax[0]] = up_ax[1]
    fr = np.zeros(3)
    fr[front_ax[0]] = front_ax[1]
    return np.array([np.cross(u, fr), u, fr])
