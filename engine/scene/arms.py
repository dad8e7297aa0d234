"""Dress a body whose arms hang close to its torso: with the arms raised, then lowered.

A top sewn on such a body fails: the seams beside the arms cannot close with an arm in the way
(engine.scene.garments.arms_in_the_way). Then (`lift_arms`, `lower_arms`):

1. The body gets the default body's skeleton fitted (engine.body.fit) and its upper arms are
   turned out about the shoulders, LIFT_STEP degrees at a time up to LIFT_MAX, until they hang
   at least ARM_GAP_OK + LIFT_MARGIN from the torso (the A-pose the seams sew reliably in).
2. The garment is placed, sewn and draped on that raised body as usual (engine.scene.tryon).
3. The arms are lowered back over LOWER_TIME (smoothstep) and held for HOLD_TIME, the cloth
   simulated on the moving body (engine.scene.walk's machinery, maps of every frame), without
   cloth-body friction so that the arms slide past the cloth instead of dragging it down.
4. On the body as loaded, the cloth relaxes without friction for RELAX_TIME and then drapes as
   usual until it settles (engine.scene.drape.drape).

A drape unsettled or tight after this says so in the report's warnings, as any drape.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from engine.body.types import Body
from engine.cloth.config import Control
from engine.cloth.model import ClothState
from engine.cloth.solver import ClothSolver
from engine.errors import InputError
from engine.scene.drape import Around, DrapeResult, Progress, drape, dressing_config, ground
from engine.scene.request import TryOnOptions
from engine.scene.tuning import Tuning

LIFT_STEP = 5.0  # degrees
LIFT_MAX = 45.0  # degrees
LIFT_MARGIN = 0.02  # m past ARM_GAP_OK
LOWER_TIME = 1.0  # s
HOLD_TIME = 0.5  # s
RELAX_TIME = 0.5  # s
FPS = 30.0


@dataclass
class ArmLift:
    rigged: Body  # the body as loaded, with a skeleton (engine.body.fit)
    raised: Body  # ... with the upper arms turned out by `degrees`
    degrees: float
    gap_loaded: float  # m: the arms' distance from the torso (engine.body.measure.arm_gap)
    gap_raised: float

    def describe(self) -> str:
        return (f"dressed with the arms raised {self.degrees:.0f} degrees (they hang "
                f"{100 * self.gap_loaded:.1f} cm from the torso, {100 * self.gap_raised:.1f} cm raised), "
                f"then lowered over {LOWER_TIME:.1f} s")


def _pose(rigged: Body, degrees: float) -> np.ndarray:
    from engine.body.motion import _rot, pose_joints
    from engine.body.rig import skin_fast

    turn = {"upperarm01.L": _rot("z", degrees), "upperarm01.R": _rot("z", -degrees)}  # left is +x
    return skin_fast(rigged.vertices, rigged.rig, pose_joints(rigged.rig, turn))


def lift_arms(body: Body) -> ArmLift | None:
    """The raised body for `body` (module doc, step 1), or None when its arms need no raising,
    or it cannot be fitted a skeleton or raised far enough."""
    from engine.body.measure import ARM_GAP_OK, measure
    from engine.scene.walk import walking_body

    try:
        gap = measure(body).arm_gap
        if not gap < ARM_GAP_OK:
            return None
        rigged = walking_body(body)
        names = set(rigged.rig.joint_names)
        if not {"upperarm01.L", "upperarm01.R"} <= names:
            return None
        deg = 0.0
        while deg < LIFT_MAX:
            deg += LIFT_STEP
            raised = Body(vertices=_pose(rigged, deg), faces=rigged.faces, name=f"{body.name} (arms raised)",
                          segments=rigged.segments, rig=None, notes=[], to_world=body.to_world)
            got = measure(raised).arm_gap
            if got >= ARM_GAP_OK + LIFT_MARGIN:
                return ArmLift(rigged=rigged, raised=raised, degrees=deg, gap_loaded=float(gap),
                               gap_raised=float(got))
    except (InputError, ValueError, np.linalg.LinAlgError):  # no skeleton fits this body: the caller's error stands
        return None
    return None


def lowering_track(lift: ArmLift):
    """The BodyTrack from the raised arms down to the body as loaded (smoothstep over LOWER_TIME),
    then HOLD_TIME still."""
    from engine.body.motion import BodyTrack, frame_velocities

    n_low, n_hold = int(round(LOWER_TIME * FPS)), int(round(HOLD_TIME * FPS))
    frames = []
    for k in range(n_low + n_hold + 1):
        x = min(1.0, k / n_low)
        frames.append(_pose(lift.rigged, lift.degrees * (1.0 - x * x * (3.0 - 2.0 * x))))
    frames = np.asarray(frames, dtype=np.float32)
    return BodyTrack(body=lift.rigged, fps=FPS, frames=frames, vel=frame_velocities(frames, FPS),
                     offsets=np.zeros((len(frames), 3)),
                     cycle_start=0, cycle_frames=0, shift=np.zeros(3), notes=[])


def lower_arms(lift: ArmLift, res: DrapeResult, request: TryOnOptions, tuning: Tuning, plan, *,
               progress: Progress | None = None, observer=None) -> DrapeResult:
    """Steps 3 and 4 of the module doc: the drape `res` made on lift.raised, on lift.rigged
    (the body as loaded). `plan`: the maps to settle against (engine.scene.tryon.plan_maps on the
    body as loaded). Returns the drape with its iterations and timing counting the new stages
    ("lowering_arms", "settling")."""
    from engine.collide.collider import MapCollider
    from engine.collide.maps import render_body_maps
    from engine.scene.walk import walk_cloth

    progress = progress or (lambda *a: None)
    track = lowering_track(lift)
    t0 = time.perf_counter()
    # part of dressing, held to the drape's strain bar: the walk's step in double precision with the
    # drape's strain limit and guard, every step checked, without friction (the arms slide past the
    # cloth), maps of every frame, the drape's stiffness and collision band
    d = tuning.drape.step
    step = replace(tuning.walk.step, precision="double", strain_guard=d.strain_guard, vm_passes=d.vm_passes,
                   contact_rounds=d.contact_rounds)
    lowering = replace(tuning, collide_every=1, walk=replace(tuning.walk, friction=0.0, step=step,
                                                             tolerance=tuning.cloth.tolerance))
    walk = walk_cloth(lift.rigged, res, request.model_copy(update={"seconds": (len(track.frames) - 1) / FPS,
                                                                   "fps": FPS, "reuse_maps": False,
                                                                   "walk_stiffness": 1.0}),
                      lowering, track=track, progress=lambda s, f, m: progress("lowering arms", f, m),
                      observer=None if observer is None else
                      (lambda stage, x, tri, bv: observer("lowering arms", x, tri, bv)))
    t_lower = time.perf_counter() - t0
    frames = walk.garment_frames
    state = ClothState(frames[-1].astype(np.float64), (frames[-1] - frames[-2]).astype(np.float64) * FPS)
    t0 = time.perf_counter()
    maps = render_body_maps(lift.rigged, texel=request.texel, window=plan.window, segments=plan.segments,
                            tol=tuning.cloth.tolerance)
    t_maps = time.perf_counter() - t0
    collider = MapCollider(maps)
    solver = ClothSolver(res.model, collider, dressing_config(request, tuning, res.self_contact[0]), dt=request.dt,
                         force_dt=request.force_dt)
    relax = int(math.ceil(RELAX_TIME / solver.dt))
    t0 = time.perf_counter()
    floor = ground(lift.rigged.vertices)
    control = Control(damping_scale=tuning.drape.damping, friction_scale=0.0, floor=floor)
    for it in range(relax):
        solver.step(state, control)
        if it % 200 == 0:
            progress("settling", 0.0, "relaxing the cloth after lowering the arms")
    t_relax = time.perf_counter() - t0
    try:
        # the cloth lies pressed between the lowered arms and the torso: checked at every step
        settling = tuning if tuning.collide_every is not None else replace(tuning, collide_every=1)
        settled = drape(res.model, state, collider, request, settling, lambda s, f, m: progress("settling", f, m),
                        observer, gravity_from=1.0, solver=solver, around=Around(floor))
    finally:
        collider.release()  # (its query helper thread)
    w = walk.report
    n_walk = int(w["frames"] * w["substeps_per_frame"])
    walk_cloth_s = w["ms_per_frame"]["cloth"] * w["frames"] / 1000
    walk_coll_s = w["ms_per_frame"]["collision"] * w["frames"] / 1000
    settle_cloth = solver.timing["cloth"]  # the relaxation and the drape (one solver)
    settle_coll = solver.timing["collision"]
    out = replace(settled, iterations={**res.iterations, "lowering_arms": n_walk,
                                       "settling": relax + settled.iterations["draping"]},
                  timing={**res.timing, "lowering_arms": t_lower, "settling": t_maps + t_relax + settled.timing["draping"],
                          "cloth_total": res.timing["cloth_total"] + walk_cloth_s + settle_cloth,
                          "collision_total": res.timing["collision_total"] + walk_coll_s + settle_coll},
                  seam_gap_max=res.seam_gap_max, snapped=res.snapped, spec=res.spec, self_contact=res.self_contact,
                  vertex_map=res.vertex_map,
                  collide_every={**res.collide_every, "lowering_arms": w["collision_every_steps"],
                                 "settling": settled.collide_every["draping"]},
                  lowering={"strain_max": float(w["strain_max"]), "penetration_mm": w["penetration_mm"],
                            "frames": int(w["frames"]), "band_mm": w["band_mm"]})
    return out


HAND_NEAR = 0.012  # m: hands closer than this to the hips or thighs (measure's hand_gap) ...
HAND_CLEAR = 0.02  # m: ... are moved out until this far, turning the arms about the shoulders (as far
# as the default bodies' A-pose hands hang from the hips: further out a hand nears the hip's flare)
CLEAR_STEP = 2.5  # degrees a step
CLEAR_MAX = LIFT_MAX  # degrees at most


def clear_arms(body: Body) -> Body:
    """The body to dress and walk: as given, or -- where its arms hang closer to its torso than
    ARM_GAP_OK, or its hands touch or nearly touch its hips or thighs (a scan with its arms
    down) -- with the arms turned out about the shoulders (the default skeleton fitted to it)
    until they hang ARM_GAP_OK + LIFT_MARGIN from the torso and the hands HAND_CLEAR from the
    hips, rigged in that pose and saying so in its notes. There is no room for cloth between an
    arm and the torso, or a hand and a thigh, that touch: the torso's cloth is caught between
    them and stretched (dressing with the arms raised and lowering them after left shirts and
    dresses 24-36 % stretched on such scans), trousers placed round the legs take the hands in,
    and a walk swings the hands into the thighs -- so such a scan is dressed and walked in an
    A-pose, as a scan in that pose would be. Returns the body unchanged when it cannot be
    fitted."""
    from engine.body.measure import ARM_GAP_OK, measure
    from engine.body.motion import _rot, pose_joints
    from engine.body.types import Rig
    from engine.scene.walk import walking_body

    m0 = measure(body)
    hands, arms = m0.hand_gap < HAND_NEAR, m0.arm_gap < ARM_GAP_OK

    def cleared(m) -> bool:
        return (not hands or not m.hand_gap < HAND_CLEAR) and (not arms or not m.arm_gap < ARM_GAP_OK + LIFT_MARGIN)

    if not (hands or arms):
        return body
    try:
        rigged = walking_body(body)
    except (InputError, ValueError, np.linalg.LinAlgError):
        return body
    rig = rigged.rig
    if not {"upperarm01.L", "upperarm01.R"} <= set(rig.joint_names):
        return body
    deg, m, v = 0.0, m0, rigged.vertices
    while not cleared(m) and deg < CLEAR_MAX:
        deg += CLEAR_STEP
        v = _pose(rigged, deg)
        m = measure(Body(vertices=v, faces=rigged.faces))
    g = pose_joints(rig, {"upperarm01.L": _rot("z", deg), "upperarm01.R": _rot("z", -deg)})
    posed = Rig(joint_names=list(rig.joint_names), parents=rig.parents, rest_transforms=g,
                skin_indices=rig.skin_indices, skin_weights=rig.skin_weights)
    why = []
    if arms:
        why.append(f"the arms hung {100 * m0.arm_gap:.1f} cm from the torso (there is no room for the cloth "
                   f"between them), {_cm(m.arm_gap)} now")
    if hands:
        why.append(f"the hands {'touched' if m0.hand_gap < 0.002 else 'nearly touched'} the hips or thighs "
                   f"({100 * m0.hand_gap:.1f} cm), {_cm(m.hand_gap)} away now")
    note = f"the arms were turned {deg:.0f} degrees out from the body for dressing and walking: {'; '.join(why)}"
    return Body(vertices=v, faces=rigged.faces, name=body.name, segments=rigged.segments, rig=posed,
                notes=list(rigged.notes) + [note], to_world=body.to_world)


def _cm(gap: float) -> str:
    return f"{100 * gap:.1f} cm" if np.isfinite(gap) and gap < 1.0 else "well clear"
