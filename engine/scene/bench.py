"""`tryon bench`: what our speed costs in accuracy, where we stop being stable, and seed 003's
Table 1 comparison of image-space against object-space collision.

    results = run_bench(quick=False, progress=print)     # dict, JSON-able
    write_bench(results, Path("out/bench"))              # report.md, results.json, *.png

Sections (issue 6): table1 (shirt and dress, image vs object space), sweeps (error against run
time over the map texel, the time step and the cloth edge, each setting's distance from a
high-resolution reference run, Pareto plot), scaling (ms per iteration against cloth vertices and
against body triangles), stability (a grid over stiffness, time step and body speed: stable,
refused with a clear error, or unstable), peer (Newton/Warp's semi-implicit cloth on the CPU, when
installed). `quick` runs a reduced version of each (under two minutes on the 2-core machine).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Callable

import numpy as np

from engine.errors import TryonError

Say = Callable[[str], None]

# seed 003, Table 1: product -> {collision: (vertices, iterations, total s, ms per iteration)}
SEED_TABLE1 = {"shirt": {"image": (1800, 82, 1.3, 15.8), "object": (1800, 149, 4.6, 30.8)},
               "dress": {"image": (3840, 130, 4.3, 33.0), "object": (3840, 150, 7.8, 52.0)}}
SEED_PRODUCT = {"shirt": "sleeveless-shirt", "dress": "dress"}  # the seed's shirt had no sleeves


def _body(name="default:female"):
    from engine.body import resolve_body

    return resolve_body(name)


def _dress(body, garment: str, h: float, texel: float = 0.005, collision: str = "image",
           dt_fraction: float = 1.0, fabric: str = "cotton", stiffness: float = 1.0):
    """One try-on; returns (DrapeResult, report, wall seconds)."""
    from engine.cloth.fabrics import get_fabric
    from engine.cloth.model import ClothParams, build_model
    from engine.garment.garment import build_garment
    from engine.scene.drape import _edge
    from engine.scene.garments import resolve_garment
    from engine.scene.request import TryOnOptions
    from engine.scene.tryon import run_tryon
    from engine.scene.tuning import Tuning

    spec, place, label = resolve_garment(garment, body, "M")
    base = ClothParams()
    params = replace(base, stiffness_scale=base.stiffness_scale * stiffness)  # x the simulated cotton
    g = build_garment(spec, h=h, place=place)
    bound = build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, get_fabric(fabric), _edge(g),
                        params).dt_bound
    request = TryOnOptions(fabric=fabric, resolution_cm=100 * h, texel_mm=1000 * texel, collision=collision,
                           dt_ms=1000 * dt_fraction * bound)
    t0 = time.perf_counter()
    res, rep = run_tryon(body, spec, request, Tuning(cloth=params), place=place, source=label)
    return res, rep, time.perf_counter() - t0


# ------------------------------------------------------------------------------------------ table 1

def _resolution_for(body, garment: str, target: int) -> float:
    from engine.garment.garment import build_garment
    from engine.scene.garments import resolve_garment

    spec, place, _ = resolve_garment(garment, body, "M")
    h = 0.03
    for _ in range(3):
        n = build_garment(spec, h=h, place=place).n_vertices
        h = h * math.sqrt(n / target)
    return float(max(h, 0.003))


def run_table1(body, quick: bool, say: Say) -> list[dict]:
    rows = []
    for product, seed in SEED_TABLE1.items():
        if quick and product == "dress":
            continue
        target = seed["image"][0] // (3 if quick else 1)
        h = _resolution_for(body, SEED_PRODUCT[product], target)
        for collision in ("image", "object"):
            try:
                res, rep, wall = _dress(body, SEED_PRODUCT[product], h, collision=collision)
            except TryonError as e:  # reported, not hidden: the row says why
                rows.append({"product": product, "collision": collision, "failed": str(e), "seed": seed[collision]})
                say(f"table1 {product} {collision}: FAILED {e}")
                continue
            ms = rep["ms_per_iteration"]
            rows.append({"product": product, "collision": collision, "vertices": rep["cloth_vertices_unsewn"],
                         "iterations": rep["iterations"], "total_s": rep["wall_seconds"]["sewing"]
                         + rep["wall_seconds"]["draping"], "ms_per_iteration": ms["total"],
                         "ms_cloth": ms["cloth"], "ms_collision": ms["collision"],
                         "penetration_max_mm": rep["penetration_mm"]["max"], "strain_max": rep["strain"]["max"],
                         "settled": rep["settled"], "seed": seed[collision]})
            say(f"table1 {product} {collision}: {rows[-1]['vertices']} v, {rows[-1]['iterations']} it, "
                f"{ms['total']:.2f} ms/it ({ms['collision']:.2f} collision)")
    return rows


# ------------------------------------------------------------------------------------------ sweeps

def _surface_distance(positions, ref_positions, ref_triangles) -> tuple[float, float]:
    """Mean and 95th-percentile distance (m) of each vertex to the reference garment's surface."""
    from engine.collide.bvh import MeshBVH

    d = np.abs(MeshBVH(ref_positions, ref_triangles).signed_distance(positions))
    return float(d.mean()), float(np.percentile(d, 95))


def run_sweeps(body, quick: bool, say: Say) -> dict:
    garment = "skirt"
    base_h = 0.02
    if quick:
        ref = dict(h=0.02, texel=0.0025, dt_fraction=0.5)
        settings = ([("texel", dict(texel=t)) for t in (0.02, 0.005)]
                    + [("dt", dict(dt_fraction=f)) for f in (1.0, 0.5)]
                    + [("edge", dict(h=h)) for h in (0.03, 0.02)])
        obj = [("edge", dict(h=0.03))]
    else:
        # (the reference keeps the eq. 4 step: halving it moved the result 0.3 mm, doubled the cost)
        ref = dict(h=0.01, texel=0.001, dt_fraction=1.0)
        settings = ([("texel", dict(texel=t)) for t in (0.02, 0.01, 0.005, 0.0025, 0.001)]
                    + [("dt", dict(dt_fraction=f)) for f in (1.0, 0.5, 0.25)]
                    + [("edge", dict(h=h)) for h in (0.03, 0.02, 0.015, 0.01, 0.0075)])
        obj = [("dt", dict(dt_fraction=1.0))] + [("edge", dict(h=h)) for h in (0.03, 0.02)]
    say(f"sweeps: reference run (edge {ref['h'] * 100:g} cm, texel {ref['texel'] * 1000:g} mm, "
        f"dt {ref['dt_fraction']:g} x bound)")
    rres, rrep, rwall = _dress(body, garment, ref["h"], texel=ref["texel"], dt_fraction=ref["dt_fraction"])
    runs, done = [], {}
    for collision, todo in (("image", settings), ("object", obj)):
        for axis, over in todo:
            kw = dict(h=base_h, texel=0.005, dt_fraction=1.0)
            kw.update(over)
            key = (collision, kw["h"], kw["texel"] if collision == "image" else None, kw["dt_fraction"])
            if key not in done:  # the base setting appears on every axis: run it once
                try:
                    done[key] = _dress(body, garment, kw["h"], texel=kw["texel"], dt_fraction=kw["dt_fraction"],
                                       collision=collision)
                except TryonError as e:
                    done[key] = e
            if isinstance(done[key], TryonError):
                runs.append({"collision": collision, "axis": axis, "edge_cm": kw["h"] * 100, "failed": str(done[key]),
                             "dt_fraction": kw["dt_fraction"],
                             "texel_mm": kw["texel"] * 1000 if collision == "image" else None})
                say(f"sweep {collision} {axis} {over}: FAILED {done[key]}")
                continue
            res, rep, wall = done[key]
            mean, p95 = _surface_distance(res.positions, rres.positions, rres.triangles)
            runs.append({"collision": collision, "axis": axis, "edge_cm": kw["h"] * 100,
                         "texel_mm": kw["texel"] * 1000 if collision == "image" else None,
                         "dt_fraction": kw["dt_fraction"], "vertices": rep["cloth_vertices"], "run_s": wall,
                         "iterations": rep["iterations"], "penetration_max_mm": rep["penetration_mm"]["max"],
                         "penetration_p99_mm": rep["penetration_mm"]["p99"], "strain_max": rep["strain"]["max"],
                         "distance_mean_mm": mean * 1000, "distance_p95_mm": p95 * 1000, "settled": rep["settled"]})
            say(f"sweep {collision} {axis} {over}: {wall:.1f} s, distance {mean * 1000:.1f} mm (p95 "
                f"{p95 * 1000:.1f}), pen max {rep['penetration_mm']['max']:.1f} mm, strain "
                f"{100 * rep['strain']['max']:.1f} %")
    return {"garment": garment, "base_edge_cm": base_h * 100, "reference": {**ref, "run_s": rwall,
            "vertices": rrep["cloth_vertices"]}, "runs": runs}


# ------------------------------------------------------------------------------------------ scaling

def _decimate(vertices, faces, cell: float, segments=None):
    """Vertex clustering on a grid of `cell` metres: a coarser body for the scaling sweep."""
    key = np.floor(vertices / cell).astype(np.int64)
    _, rep, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.ravel()
    cnt = np.bincount(inv)
    v = np.zeros((len(rep), 3))
    np.add.at(v, inv, vertices)
    v /= cnt[:, None]
    f = inv[faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]  # collapsed triangles out
    _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)  # duplicates out, order kept
    f = f[np.sort(first)]
    seg = None if segments is None else segments[rep]
    return v, f.astype(np.int32), seg


def _ms_per_iteration(body, garment: str, h: float, collision: str, steps: int) -> tuple[float, int, float]:
    """ms per iteration of the first `steps` sewing steps (after a warm-up), maps time (s)."""
    from engine.cloth.fabrics import get_fabric
    from engine.cloth.model import ClothState, build_model
    from engine.cloth.solver import ClothSolver
    from engine.garment.garment import build_garment
    from engine.scene.drape import _edge
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import plan_maps

    spec, place, _ = resolve_garment(garment, body, "M")
    g = build_garment(spec, h=h, place=place)
    model = build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, get_fabric("cotton"), _edge(g))
    t0 = time.perf_counter()
    if collision == "image":
        from engine.collide.collider import MapCollider
        from engine.collide.maps import render_body_maps

        plan = plan_maps(body, g, 0.005, "image")
        collider = MapCollider(render_body_maps(body, texel=0.005, window=plan.window, segments=plan.segments))
    else:
        from engine.collide.bvh import ObjectSpaceCollider

        collider = ObjectSpaceCollider(body.vertices, body.faces, tolerance=0.005)
    t_maps = time.perf_counter() - t0
    solver = ClothSolver(model, collider)
    state = ClothState(g.positions.copy(), np.zeros_like(g.positions))
    for _ in range(WARM_STEPS):
        solver.step(state)
    t0 = time.perf_counter()
    for _ in range(steps):
        solver.step(state)
    ms = 1000 * (time.perf_counter() - t0) / steps
    collider.release()  # (the map collider's query helper thread)
    return ms, model.n, t_maps


WARM_STEPS = 40  # steps before a timing: the kernels compiled or loaded, the collider's query helper
# thread started (its start, ~1-2 ms once, fell inside 20 timed steps after a warm-up of 5:
# 0.20 instead of 0.12 ms an iteration for the 1,016-vertex skirt, and the quick bench's scaling
# fit lost its straight line in the slow suite, r2 0.64)


def run_scaling(body, quick: bool, say: Say) -> dict:
    from engine.body.types import Body

    targets = (1000, 4000, 16000) if quick else (1000, 4000, 16000, 64000)
    cloth = []
    for n in targets:
        h = _resolution_for(body, "skirt", n)
        for collision in ("image",) + (("object",) if n <= 16000 else ()):
            ms, nv, _ = _ms_per_iteration(body, "skirt", h, collision, 20 if quick else 60)
            cloth.append({"collision": collision, "vertices": nv, "ms_per_iteration": ms})
            say(f"scaling cloth {collision}: {nv} v, {ms:.2f} ms/it")
    fits = {}
    for collision in ("image", "object"):
        pts = [(r["vertices"], r["ms_per_iteration"]) for r in cloth if r["collision"] == collision]
        if len(pts) >= 2:
            x, y = np.array(pts, float).T
            a, b = np.polyfit(x, y, 1)
            r2 = 1 - np.sum((y - (a * x + b)) ** 2) / max(np.sum((y - y.mean()) ** 2), 1e-30)
            fits[collision] = {"ms_per_1000_vertices": a * 1000, "intercept_ms": b, "r2": float(r2)}
    import trimesh

    bodies = []
    levels = [("decimated 3 cm", 0.03), ("decimated 1.5 cm", 0.015), ("as built", None)]
    if not quick:
        levels += [("subdivided once", "sub"), ("subdivided twice", "sub2")]
    for label, how in levels:
        if how is None:
            b = body
        elif how in ("sub", "sub2"):
            v, f = trimesh.remesh.subdivide(body.vertices, body.faces)
            if how == "sub2":
                v, f = trimesh.remesh.subdivide(v, f)
            seg = None
            if body.segments is not None:  # new midpoints take a neighbour's label
                from scipy.spatial import cKDTree

                seg = body.segments[cKDTree(body.vertices).query(v)[1]]
            b = Body(v, f.astype(np.int32), segments=seg)
        else:
            v, f, seg = _decimate(body.vertices, body.faces, how, body.segments)
            b = Body(v, f, segments=seg)
        row = {"body": label, "triangles": int(len(b.faces))}
        for collision in ("image", "object"):
            ms, nv, tm = _ms_per_iteration(b, "skirt", 0.03, collision, 20 if quick else 60)
            row[f"{collision}_ms_per_iteration"] = ms
            row[f"{collision}_setup_s"] = tm
        bodies.append(row)
        say(f"scaling body {label}: {row['triangles']} triangles, image {row['image_ms_per_iteration']:.2f} "
            f"ms/it, object {row['object_ms_per_iteration']:.2f} ms/it")
    return {"cloth": cloth, "fits": fits, "bodies": bodies}


# ------------------------------------------------------------------------------------------ stability

def _static_track(body, fps: float = 30.0):
    from engine.body.motion import BodyTrack

    f = body.vertices[None].astype(np.float32)
    return BodyTrack(body=body, fps=fps, frames=f, vel=np.zeros_like(f), offsets=np.zeros((1, 3)), cycle_start=0,
                     cycle_frames=1, shift=np.zeros(3), notes=["standing still"])


def run_stability(body, quick: bool, say: Say) -> dict:
    """The coarse skirt (3 cm) is dressed once (cotton); each cell then runs it for 0.3 s with
    the cell's stiffness (x the simulated cotton: springs and their damping scaled, the eq. 4
    bound with them), time step (x that bound) and body speed (0: standing; else walking, 0.15 s
    from rest to the full walk). Outcome: stable; refused (a clear error: a time step above the
    eq. 4 bound is refused unless forced); unstable (non-finite, runaway strain or cloth flying
    off -- the walk stops itself with SimulationError -- or any other exception: a bug)."""
    from engine.body.motion import WalkParams, walk_track
    from engine.errors import InputError, SimulationError
    from engine.scene.request import TryOnOptions
    from engine.scene.walk import walk_cloth

    stiff = (1.0, 100.0) if quick else (0.1, 1.0, 10.0, 100.0)
    fracs = (1.0, 1.5) if quick else (0.25, 0.5, 1.0, 1.5)
    speeds = (0.0, 3.6) if quick else (0.0, 1.2, 3.6)
    tracks = {s: (walk_track(body, WalkParams(speed=s, ramp=0.15), 30) if s > 0 else _static_track(body))
              for s in speeds}
    base, _, _ = _dress(body, "skirt", 0.03)
    cells = []
    for k in stiff:
        m = base.model
        model = replace(m, stiffness=m.stiffness * k, spring_c=m.spring_c * math.sqrt(k),
                        dt_bound=m.dt_bound / math.sqrt(k))
        for f in fracs:
            drape = replace(base, model=model, dt=f * model.dt_bound)
            for s in speeds:
                cell = {"stiffness": k, "dt_fraction": f, "speed": s}
                try:
                    w = walk_cloth(body, drape, TryOnOptions(seconds=0.3, walk_stiffness=1.0), track=tracks[s])
                    cell.update(outcome="stable", strain_max=w.report["strain_max"],
                                penetration_max_mm=w.report["penetration_mm"]["max"])
                except InputError as e:
                    cell.update(outcome="refused", reason=str(e))
                except SimulationError as e:  # NaN, runaway strain, flying off: the walk stopped itself
                    cell.update(outcome="unstable", reason=str(e))
                except Exception as e:  # a bug
                    cell.update(outcome="unstable", reason=f"{type(e).__name__}: {e}")
                cells.append(cell)
                say(f"stability k x{k:g} dt x{f:g} speed {s:g}: {cell['outcome']}"
                    + (f" ({cell.get('reason', '')[:80]})" if cell["outcome"] != "stable" else ""))
    return {"stiffness": list(stiff), "dt_fraction": list(fracs), "speed": list(speeds), "cells": cells,
            "unstable": sum(c["outcome"] == "unstable" for c in cells)}


# ------------------------------------------------------------------------------------------ peer

def run_peer(quick: bool, say: Say) -> dict:
    """A hanging cloth (square, pinned along one edge, no body): our step against Newton's
    semi-implicit Euler cloth (Warp kernels on the CPU), same vertex count, same stiffness."""
    import importlib.util

    missing = [m for m in ("warp", "newton") if importlib.util.find_spec(m) is None]
    if missing:  # not installed: say so (make bench-peer installs them)
        return {"available": False, "reason": f"{' and '.join(missing)} not installed; install them with "
                                              "`make bench-peer`"}
    from engine.scene.bench_peer import compare

    return compare(quick, say)


# ------------------------------------------------------------------------------------------ all

def run_bench(quick: bool = False, progress: Say | None = None) -> dict:
    say = progress or (lambda m: None)
    body = _body()
    t0 = time.perf_counter()
    out = {"quick": quick, "machine": _machine()}
    for name, fn in (("stability", lambda: run_stability(body, quick, say)),
                     ("scaling", lambda: run_scaling(body, quick, say)),
                     ("table1", lambda: run_table1(body, quick, say)),
                     ("sweeps", lambda: run_sweeps(body, quick, say)),
                     ("peer", lambda: run_peer(quick, say))):
        t = time.perf_counter()
        out[name] = fn()
        out.setdefault("section_seconds", {})[name] = time.perf_counter() - t
    out["total_seconds"] = time.perf_counter() - t0
    return out


def _machine() -> dict:
    import os
    import platform

    return {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()}
