"""Walk a dressed body (seed 000 end to end): dress it standing (engine.scene.tryon), then play a
BodyTrack and let the cloth follow.

Per body frame (1/fps s): the solver takes whole steps of at most the eq. 4 bound; before each
step that checks collisions (ClothSolver.checks_next; the steps between do not ask the collider)
the collider is put at the step's end time (maps of the nearest frame, surface moved along
its velocity, root offset interpolated: engine.collide.moving). The collision response is
relative to the body's velocity (seed 000 eq. 15), the reaction force (eq. 16) holds cloth
pressed on the body, and the strain limit is eq. 5's average by default; the directional vector
v_dir = g dt + v_object (eq. 6 and §3.2's two rules) can be chosen, but is not yet stable here
(TryOnOptions.velocity_mode). Damping is the fabric's own
(the drape's extra settling damping is off: walking is dynamic).

Softer springs while walking (TryOnOptions.walk_stiffness, default 0.25 x the drape's stretch and
shear springs): the eq. 4 step grows as 1 / sqrt of it, and the strain limit (velocity
modification, the strain guard) holds the fit, as in seed 003 §4. Where it cannot -- a band the
moving body wedges -- a frame whose strain passes the fabric's threshold + WalkTuning.stiffen_at
over at least WalkTuning.stiffen_springs springs (spread_strain), or three times that at one,
doubles the stiffness (up to the drape's) for the rest of the walk and the report says so.

A periodic walk's maps (the ramp and one cycle) are rendered before the walking stage
(WalkTuning.prerender; `map_prerender_seconds`), and the walk expands their float16 copies.
Otherwise the maps of each frame are rendered one frame ahead in a helper thread with its own
GL context (WalkTuning.render_ahead; engine.collide.moving): the body's motion does not depend
on the cloth, and the numba kernels release the GIL, so the render runs on the second core while
the solver works; the solver waits only when a render is late (`ms_per_frame.maps` counts that
wait, `map_render_seconds` the renders). The maps are the same bit for bit (tests/test_walk.py).

Each frame is checked: non-finite positions, runaway strain or cloth far from the body end the run
with SimulationError (never an exploded garment written as a result).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from engine.body.motion import BodyTrack, walk_track
from engine.body.types import SEGMENTS, Body
from engine.cloth.config import Control
from engine.cloth.model import ClothState, spring_strains, with_stiffness
from engine.cloth.solver import ClothSolver
from engine.errors import SimulationError
from engine.scene.drape import DrapeResult, Progress, ground
from engine.scene.request import TryOnOptions
from engine.scene.tuning import Tuning, WalkTuning

RUNAWAY_STRAIN = 0.5  # a spring stretched 50 % past its rest length: the cloth is exploding
FLY_OFF = 0.5  # m: a cloth vertex this far outside the body's bounding box has left it


def check_every(track: BodyTrack, dt: float, tuning: WalkTuning = WalkTuning()) -> float:
    """Solver steps between collision checks while walking, on average (engine.cloth.schedule):
    as many as the body's bulk travel (its vertices' mean velocity, fastest frame) takes to cover
    check_travel, 1 .. max_check_every, to 0.01 of a step (not rounded down to whole steps)."""
    bulk = float(np.linalg.norm(track.vel.mean(axis=1, dtype=np.float64), axis=1).max())
    return float(np.clip(math.floor(100.0 * tuning.check_travel / max(bulk * dt, 1e-12)) / 100.0, 1,
                         tuning.max_check_every))


@dataclass
class WalkResult:
    garment_frames: np.ndarray  # (F, M, 3) float32 cloth positions per frame (frame 0: the drape)
    triangles: np.ndarray  # (T, 3) int32
    track: BodyTrack
    report: dict


def walking_body(body: Body) -> Body:
    """The body to walk: a scan (no rig) gets the default body's skeleton and weights fitted to it
    (engine.body.fit); a rigged body walks as it is. The scan is dressed as loaded (dressed with
    the fitted segment maps, the sample skirt on the sample scan was left at 17 % strain)."""
    if body.rig is not None:
        return body
    from engine.body.fit import fit_rig

    return fit_rig(body)


def walk_segments(body: Body, track: BodyTrack, garment_top: float) -> tuple[list[str] | None, list[str]]:
    """Segment maps for a walk: every limb the garment can meet while walking (the arms swing
    down past the hips, so unlike a standing skirt a walking one needs them), the head only when
    the garment reaches the neck. Returns (segments or None for one whole-body map, left out)."""
    if body.segments is None:
        return None, ["segment maps, because this body has no segment labels (one whole-body map pair)"]
    present = set(int(s) for s in np.unique(body.segments))
    segs = [s for s in ("torso", "left_arm", "right_arm", "left_leg", "right_leg") if SEGMENTS.index(s) in present]
    left = []
    head = body.segments == SEGMENTS.index("head")
    if head.any() and garment_top + 0.05 > float(body.vertices[head, 1].min()):
        segs = ["head"] + segs
    else:
        left.append("head maps, because the garment stays below the neck")
    arm = np.isin(body.segments, [SEGMENTS.index("left_arm"), SEGMENTS.index("right_arm")])
    lowest = min(float(track.frames[k][arm, 1].min()) for k in range(len(track.frames))) if arm.any() else np.inf
    if lowest > garment_top + 0.05:
        segs = [s for s in segs if "arm" not in s]
        left.append(f"arm maps, because the arms never come down to the garment (lowest {lowest:.2f} m, "
                    f"garment top {garment_top:.2f} m)")
    return segs, left


def walk_cloth(body: Body, drape: DrapeResult, request: TryOnOptions = TryOnOptions(), tuning: Tuning = Tuning(), *,
               progress: Progress | None = None, track: BodyTrack | None = None, observer=None) -> WalkResult:
    """Walk `body` wearing the draped garment `drape` for request.seconds (the procedural walk,
    or `track`). observer: called every frame (engine.scene.drape.Observer, with the body's
    vertices of the frame; both meshes relative to the root's horizontal travel, so that a viewer
    keeps the walker in view)."""
    progress = progress or (lambda *a: None)
    t = tuning.walk
    tuning.validate()
    t_all = time.perf_counter()
    progress("motion", 0.0, "posing the walk")
    if track is None:
        track = walk_track(body, request.walk, request.fps)
    left = list(track.notes)
    n_frames = int(round(request.seconds * track.fps))
    if not track.periodic and n_frames > len(track.frames) - 1:
        n_frames = len(track.frames) - 1
        left.append(f"walking past {n_frames / track.fps:.2f} s, because the animation ends there")
    collider, renderer = _walk_collider(body, drape, track, request, t, n_frames, left)
    frame_time = 1.0 / track.fps
    t_prerender = 0.0
    if request.collision == "image" and t.prerender and collider.keep:
        progress("walk maps", 0.0, "rendering the walk's collision maps")
        t_prerender = collider.prerender(n_frames, lambda k, n: progress(
            "walk maps", k / n, f"collision maps of frame {k}/{n} of the ramp and one cycle"))

    def walking_model(stiffness: float):
        """The drape's model at `stiffness` x its springs, the substeps a frame, the step (the
        drape's, scaled as the eq. 4 bound is) and the steps between collision checks."""
        m = with_stiffness(drape.model, stiffness, damping_cap=t.damping_cap)
        if m.params.tolerance != t.tolerance:
            m = replace(m, params=replace(m.params, tolerance=t.tolerance))
        dt_max = drape.dt * m.dt_bound / drape.model.dt_bound
        n_sub = max(1, math.ceil(frame_time / dt_max - 1e-9))
        ev = tuning.collide_every if tuning.collide_every is not None else check_every(track, frame_time / n_sub, t)
        return m, n_sub, frame_time / n_sub, ev

    stiffness = request.walk_stiffness
    model, sub, dt, every = walking_model(stiffness)
    stiffened = []
    stiffen_strain = model.fabric.strain_threshold + t.stiffen_at if t.stiffen_at is not None else np.inf
    step = replace(t.step, velocity_mode=request.velocity_mode)
    solver = ClothSolver(model, collider, step, dt=dt)
    # (the ground under the walk's soles: a hem that lay on the floor stays on it)
    control = Control(friction_scale=t.friction, collide_every=every,
                      floor=ground(track.frames.reshape(-1, 3)))
    state = ClothState(drape.state.x.copy(), drape.state.v.copy())
    frames = np.empty((n_frames + 1, model.n, 3), np.float32)
    frames[0] = state.x
    strains = []
    lo, hi = body.vertices.min(axis=0), body.vertices.max(axis=0)
    t_maps = t_cloth = t_coll = 0.0
    t_walk0 = time.perf_counter()
    try:
        for i in range(1, n_frames + 1):
            m0, c0, k0 = collider.stats["map_seconds"], solver.timing["cloth"], solver.timing["collision"]
            for s in range(sub):
                if solver.checks_next(control):  # (the steps between checks do not ask the collider)
                    collider.set_time((i - 1 + (s + 1) / sub) * frame_time)
                solver.step(state, control)
            solver.finish_guard(state)  # (the late guard: the frame's last step's guard)
            t_maps += collider.stats["map_seconds"] - m0
            t_cloth += solver.timing["cloth"] - c0
            t_coll += solver.timing["collision"] - k0
            x = state.x
            strain = _check_frame(solver, state, i, track, lo, hi)
            frames[i] = x
            # the strain limit is losing over a region, or badly at one spring: stiffer springs
            spread = spread_strain(model, x, t.stiffen_springs) if strain > stiffen_strain else 0.0
            if (spread > stiffen_strain or strain > stiffen_strain + 2 * t.stiffen_at) and stiffness < 1.0:
                stiffness = min(1.0, 2.0 * stiffness)
                model, sub, dt, every = walking_model(stiffness)
                solver.restiffen(model, dt)
                control.collide_every = every
                stiffened.append({"frame": i, "strain": strain, "stiffness": stiffness})
                why = (f"{t.stiffen_springs} springs reached {100 * spread:.1f} %" if spread > stiffen_strain else
                       f"a spring reached {100 * strain:.1f} %")
                left.append(f"the softer walking springs from frame {i} on ({stiffness:g} x the drape's now), "
                            f"because {why} strain")
            strains.append(strain)
            progress("walking", i / n_frames, f"frame {i}/{n_frames}, strain {100 * strain:.1f} %")
            if observer is not None:  # a viewer follows the walker: both relative to the root
                off = track.offset(i)
                observer("walking", x - off, drape.triangles, track.vertices(i) - off)
        wall_walk = time.perf_counter() - t_walk0
    finally:
        collider.release()  # (its query server's thread; rendered ahead: the helper thread's renderer)
        if renderer is not None:
            renderer.release()
    # the exact penetration check of every frame, after the walking stage (its parallel BVH
    # queries would take the cores the walk uses)
    tp = time.perf_counter()
    per_frame, pooled = _penetration(body, track, frames, strains, progress)
    t_pen = time.perf_counter() - tp
    sim_seconds = n_frames * frame_time
    report = {
        "frames": n_frames, "fps": track.fps, "seconds": sim_seconds, "substeps_per_frame": sub, "dt_ms": dt * 1000,
        "collision_every_steps": every,
        "stiffness": {"start": request.walk_stiffness, "end": stiffness, "stiffened": stiffened},
        "damping_cap": t.damping_cap,  # x m / (dt degree): the cap on each spring's damping
        "late_guard": step.late_guard,  # the strain guard from the next force pass's list
        "flexion_every": step.flexion_every,  # steps between the flexion (and held shear) springs' forces
        "contact_rounds": step.contact_rounds,
        "push_time_ms": step.push_time * 1000,
        # the collision band the cloth kept while walking: the solver's and the moving body's
        "band_mm": {"cloth": model.params.tolerance * 1000, "body": collider.tol * 1000},
        "strain_guard": step.strain_guard,
        "velocity_mode": step.velocity_mode,
        "realtime_factor": sim_seconds / max(wall_walk, 1e-9),
        "ms_per_frame": {"maps": 1000 * t_maps / n_frames, "cloth": 1000 * t_cloth / n_frames,
                         "collision": 1000 * t_coll / n_frames, "total": 1000 * wall_walk / n_frames},
        "map_frames_rendered": collider.stats["renders"], "map_frames_reused": collider.stats["reuses"],
        # the renders' own time (ms_per_frame.maps counts what the walk waited for: rendered ahead,
        # in a helper thread, only their lateness)
        "map_render_seconds": collider.stats.get("render_seconds", collider.stats["map_seconds"]),
        # ... of them, those rendered before the walking stage (not in its wall time)
        "map_prerender_seconds": t_prerender,
        "maps_rendered_ahead": t.render_ahead and request.collision == "image",
        "map_memory_mb": collider.stats["map_bytes"] / 2 ** 20,
        # the collision queries' chunks answered by the query server's thread (the rest: the solver's)
        "query_server_share": _server_share(collider.stats.get("query_chunks")),
        # ... let go at this time (s) when it kept making the solver wait (engine.collide.server.StallWatch)
        "query_helper_let_go_at": collider.stats.get("helper_let_go_at"),
        "penetration_mm": {"max": float(pooled.max()) * 1000, "p99": float(np.percentile(pooled, 99)) * 1000},
        "strain_max": max(f["strain_max"] for f in per_frame),
        "wall_seconds": {"walking": wall_walk, "penetration_check": t_pen, "maps_before": t_prerender,
                         "total": time.perf_counter() - t_all},
        "left_out": left,
        "per_frame": per_frame,
    }
    return WalkResult(garment_frames=frames, triangles=drape.triangles, track=track, report=report)


def _walk_collider(body: Body, drape: DrapeResult, track: BodyTrack, request: TryOnOptions, t: WalkTuning,
                   n_frames: int, left: list[str]):
    """The walking body as a collider (maps per frame, or the object-space baseline), and the
    map renderer this thread owns (None when the helper thread renders); adds to `left` what the
    walk's maps leave out."""
    from engine.collide.maps import MapRenderer
    from engine.collide.moving import TrackCollider, TrackObjectCollider

    tol = t.tolerance
    if request.collision == "object":
        left.append("collision maps, because object-space collision (a BVH refitted every frame) was chosen")
        return TrackObjectCollider(track, tol=tol), None
    top = float(drape.positions[:, 1].max())
    segs, seg_left = walk_segments(body, track, top)
    left += seg_left
    window = (0.0, min(float(track.frames[:, :, 1].max()), top + 0.15))

    def make_renderer(own_context: bool = False) -> MapRenderer:
        return MapRenderer(body.faces, segments=body.segments, segment_names=segs, texel=request.texel, tol=tol,
                           window=window, with_velocity=True, own_context=own_context)

    keep = track.periodic and request.reuse_maps
    if keep:
        distinct = min(n_frames + 1, len(track.frames))
        left.append(f"maps of frames after the first cycle, because the walk is periodic: {distinct} frames "
                    f"of maps rendered once (ramp {track.cycle_start} + cycle {track.cycle_frames}) and "
                    f"reused for all {n_frames + 1} frames (float16 copies)")
    else:
        left.append("nothing: the motion is not periodic, so maps are rendered for every frame")
    if t.render_ahead:  # the helper thread makes the renderer
        collider = TrackCollider(track, lambda: make_renderer(own_context=True), tol=tol, keep=keep, ahead=True)
        collider.last_frame = n_frames
        return collider, None
    renderer = make_renderer()
    return TrackCollider(track, renderer, tol=tol, keep=keep), renderer


def spread_strain(model, x: np.ndarray, n: int) -> float:
    """The strain of the n-th most stretched of the model's strain-limited springs at positions x."""
    _, strain = spring_strains(model, x)
    if len(strain) == 0:
        return 0.0
    n = min(n, len(strain))
    return float(np.partition(strain, len(strain) - n)[len(strain) - n])


def _check_frame(solver: ClothSolver, state: ClothState, i: int, track: BodyTrack, lo: np.ndarray,
                 hi: np.ndarray) -> float:
    """The frame's strain max; SimulationError when the cloth became unstable or came apart."""
    x = state.x
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(state.v))):
        raise SimulationError(f"the cloth became unstable at frame {i} ({i / track.fps:.2f} s; non-finite "
                              "positions); walk slower or use a softer fabric")
    strain = solver.max_strain(state)
    off = track.offset(i)
    far = float(np.max(np.maximum(lo + off - x, x - hi - off)))
    if strain > RUNAWAY_STRAIN or far > FLY_OFF:
        what = (f"a spring is stretched {100 * strain:.0f} %" if strain > RUNAWAY_STRAIN
                else f"cloth is {far:.2f} m outside the body's box")
        raise SimulationError(f"the garment came apart at frame {i} ({i / track.fps:.2f} s: {what}); "
                              "walk slower, or use a smaller size or a softer fabric")
    return strain


def _penetration(body: Body, track: BodyTrack, frames: np.ndarray, strains: list, progress: Progress):
    """Each frame's cloth against that frame's body mesh, exactly: (per-frame figures, every
    vertex's depth of every frame)."""
    from engine.collide.bvh import MeshBVH, penetration_depth

    progress("penetration", 0.0, "checking every frame against the body")
    exact, per_frame, depths = None, [], []
    n_frames = len(frames) - 1
    for i in range(1, n_frames + 1):
        bv = track.vertices(i)
        if exact is None:
            exact = MeshBVH(bv, body.faces)
        else:
            exact.update(bv)  # same topology: refit
        depth, _ = penetration_depth(exact, frames[i])
        depths.append(depth.astype(np.float32))
        per_frame.append({"frame": i, "t": round(i / track.fps, 4),
                          "penetration_mm": {"max": float(depth.max()) * 1000,
                                             "p99": float(np.percentile(depth, 99)) * 1000},
                          "strain_max": strains[i - 1]})
        progress("penetration", i / n_frames, f"frame {i}/{n_frames}")
    return per_frame, np.concatenate(depths)


def _server_share(chunks: dict | None) -> float | None:
    """The query server's share of the queries' chunks (None: no server, object-space collision)."""
    if not chunks or not (chunks["server"] + chunks["solver"]):
        return None
    return chunks["server"] / (chunks["server"] + chunks["solver"])


def walk_report(drape_report: dict, walk: dict) -> dict:
    """The walk's report: the drape's fields (dressing the standing body), then the walk's
    headline fields at the top level (frames, fps, realtime_factor, ms_per_frame, per_frame),
    the rest under "walk"; left_out holds both stages' choices."""
    top = ("frames", "fps", "realtime_factor", "ms_per_frame", "per_frame")
    out = dict(drape_report)
    out.update({k: walk[k] for k in top})
    out["walk"] = {k: v for k, v in walk.items() if k not in top and k != "left_out"}
    out["left_out"] = list(drape_report.get("left_out", [])) + list(walk.get("left_out", []))
    return out


def write_walk_outputs(out, body: Body, walk: WalkResult, report: dict, panels: int = 8,
                       size: int = 420) -> list:
    """anim.glb (body + garment moving), strip.png (a row of side views across the walk) and
    report.json in `out`; returns the paths."""
    import json
    from pathlib import Path

    from PIL import Image

    from engine.io.anim import write_anim_glb
    from engine.io.export import BODY_RGBA, GARMENT_RGBA

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tr, gf = walk.track, walk.garment_frames
    body_frames = np.stack([tr.vertices(i).astype(np.float32) for i in range(len(gf))])
    paths = [write_anim_glb(out / "anim.glb", [("body", body.faces, body_frames, BODY_RGBA),
                                              ("garment", walk.triangles, gf, GARMENT_RGBA)], fps=tr.fps)]
    p = out / "strip.png"
    Image.fromarray(walk_strip(body, walk, panels, size)).save(p)
    paths.append(p)
    p = out / "report.json"
    p.write_text(json.dumps(report, indent=2))
    paths.append(p)
    return paths


def walk_strip(body: Body, walk: WalkResult, panels: int = 8, size: int = 420) -> np.ndarray:
    """(size, W, 3) uint8: side views of `panels` frames across the walk, each centred on the
    walker, side by side."""
    from engine.io.render import BODY_RGB, render_meshes

    tr, gf = walk.track, walk.garment_frames
    picks = np.unique(np.linspace(0, len(gf) - 1, panels).round().astype(int))
    imgs = []
    for i in picks:
        off = np.array([0.0, 0.0, tr.offset(int(i))[2]])  # each panel centred on the walker
        imgs.append(render_meshes([(tr.vertices(int(i)) - off, body.faces, BODY_RGB),
                                   (gf[i] - off, walk.triangles, (0.27, 0.43, 0.75))], size=size, view="side"))
    h = min(im.shape[0] for im in imgs)
    return np.concatenate([im[:h] for im in imgs], axis=1)
