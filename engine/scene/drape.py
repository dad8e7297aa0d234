"""Dress a standing body (seed 003 end to end): sew the placed panels, then drape.

Stages end on measured conditions within a bounded budget of simulated time:
- sew: friction off (the panels slide over the body into place), gravity ramped in over
  `gravity_ramp` so the seams catch before the panels fall; each open stitch pair is given the
  relative velocity that closes it in `sew_tau` (a velocity modification, after the strain limit
  and before the collision response); a pair closer than `weld_gap` is welded (moves as one
  point); when every pair is welded the sewn vertices are merged, with flexion springs across
  the seams (engine.cloth.model.seam_flexion). Panels laid out far apart (GarmentCode's flat
  layout, `far_gap`) are sewn at the drape's damping, so they do not swing on when they meet.
  If the budget runs out first, SimulationError names the seams that stayed open and their gaps.
- drape: gravity (still growing where sewing ended, to g within `fire_ramp`), the cloth brought
  to rest by FIRE (engine.cloth.solver.FireRelaxer: velocities zeroed whenever the cloth starts
  swinging back) rather than by heavy viscous damping, until the cloth's shape stops moving:
  RMS vertex displacement over each of the last two `settle_time` windows, as a speed, below
  `settle_speed` (tested every 1/SETTLE_CHECKS of a window, so a drape ends within a fifth of a
  window of settling, not up to a window later). A garment left stretched more than `too_tight`
  past the fabric's strain threshold is refused as too small (SimulationError),
  early when it stays so for `refuse_after` once `drape_min` has passed.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from engine.cloth.fabrics import get_fabric
from engine.cloth.model import FLEXION, ClothModel, ClothParams, ClothState, build_model, weld_model
from engine.cloth.solver import ClothSolver, Collider, FireRelaxer
from engine.cloth.welds import hold_welds, merge_map, seam_gaps
from engine.errors import InputError, SimulationError
from engine.garment.garment import Garment

FELL_BELOW = -0.05  # m: cloth wholly below this height has fallen off the body (feet stand on y = 0)
SETTLE_CHECKS = 5  # the settle test runs this many times a window (on the two windows just ended)
Progress = Callable[[str, float, str], None]  # (stage, fraction 0..1, message)
# (stage, cloth positions (N, 3), triangles (F, 3), body vertices (M, 3) or None when unchanged):
# called every `observe_every` s of simulated time, e.g. to stream the cloth to a viewer
Observer = Callable[[str, np.ndarray, np.ndarray, "np.ndarray | None"], None]


SEW_CHECK_MAX = 3  # most steps between collision checks while sewing (DrapeOptions.sew_check_travel) ...
DRAPE_CHECK_MAX = 2  # ... and while draping (DrapeOptions.drape_check_time)
TIGHT_GRACE = 0.025  # s: draping time before a strain past the bar makes it check every step (DrapeOptions.tight_every_step)


@dataclass
class DrapeOptions:
    fabric: str = "cotton"
    dt: float | None = None  # None: the eq. 4 bound
    force_dt: bool = False
    params: ClothParams = field(default_factory=ClothParams)
    weld_gap: float | None = None  # m: a seam pair this close is welded (None: half a cloth edge;
    # at one edge the last welds snapped pairs 11-13 mm apart together)
    sew_tau: float = 0.02  # s: a seam pair is pulled to close its gap in this time ...
    sew_vmax: float = 3.0  # m/s: ... at most this fast. The cap is what binds (default:female's M
    # dress: 19 -> 1.6 cm in 0.14 s; tau 0.01 alone: 7 % fewer sewing iterations). Measured on
    # 2026-12-04, tau 0.005 and 10 m/s over the catalogue's five garments in M on default:female
    # and default:male: sewing 2,376 iterations instead of 5,288, but the ten drapes 26,950 in
    # all instead of 28,497 (-5 %): the drapes after it from -32 % to +81 % (default:male's shirt
    # 2,046 -> 3,696), more sharp folds on the dress (8 instead of 4)
    far_retry_vmax: float = 1.5  # m/s: flat panels (far_gap) whose seams stopped closing are sewn once
    # more from their placement, pulled at most this fast (0: not). Measured on GarmentCode's own
    # T-shirt (shirt_mean, its repository's assets) on the sample body it is laid out round: at
    # 3 m/s the sleeves' seams stalled 9 cm open at 1.2, 1.5, 2 and 3 cm cloth; at 1.5 m/s all
    # four sewed and draped (strain 5.4-5.7 %, no penetration). Not the first pull: the sample
    # skirt hangs cleaner at 3 m/s (0-5 sharp folds at those resolutions; at 1.5 m/s 5-21 and
    # its waistband creased at the back)
    sew_damping: float = 20.0  # x the viscous damping while sewing (no flapping) ...
    far_sew_damping: float = 1000.0  # ... or this (as while draping) when the stitch pairs start a
    far_gap: float = 0.2  # m: median of more than this apart: flat panels laid out around the
    # body, as GarmentCode places them (the sample skirt: 30 cm; the catalogue's panels, wrapped
    # round the body by landmarks: 0.4-12.7 cm). Measured with sharp_folds (edges folded over
    # > 150 degrees): the sample skirt, its side seams pulled shut at up to sew_vmax, at 20 x swung
    # on past welding, the hem flew up to the hips and stayed crumpled with the waistband askew in
    # 2 of 4 runs whose vertices differed by 1e-9 cm (74-88 sharp edges; the good ones 9-16); zero
    # velocities at the weld: 8-56; at 500 x: 5-17 over 4 runs, at 1000 x 0-29 over 8, all
    # hanging. Not for every garment: at 500-1000 x the shirt's underarm seams on a scan with
    # its arms 2.4 cm from the torso closed as loaded (instead of stalling, which raises the
    # arms: engine.scene.arms), and the drape ended 7-17 % stretched between arm and torso
    retry_stall: float = 0.25  # s: ... and whose largest gap shrank < 1 mm over each of two windows
    # this long (from 2 x this on). Measured on that T-shirt at 1.5 cm: the first pull's widest
    # gap stayed 9.0-9.3 cm from ~0.15 s of sewing on; judged over 0.5 s windows from 1 s, the
    # retry began after 8.6 s of wall time (13.3 s in all)
    calm_start: float = 0.05  # s: sewing starts at far_sew_damping for this long, so the strain a
    # placement leaves (a catalogue trouser's crotch, wrapped between the legs, starts up to 60 %
    # stretched) relaxes without flinging the cloth: measured on default:male's M trousers (sewn
    # in 0.03 s), a fold pressed flat across the front at 20 x (31 sharp edges), none at 1000 x (2)
    sew_friction: float | None = None  # x the fabric's friction while sewing; None: 0 (the panels
    # slide over the body into place), or ARMS_CLOSE_SEW_FRICTION on a body whose arms hang close
    # to its torso (engine.scene.tryon.sewing_friction decides)
    seam_flexion: bool = True  # bending springs across the sewn seams (engine.cloth.model.seam_flexion;
    # alone, at 20 x sewing damping, it did not keep the sample skirt's hem from crumpling)
    sew_gravity: float = 1.0  # x gravity while sewing (a flared skirt without gravity opens into a disc)
    drape_damping: float = 1000.0  # x the viscous damping while draping (a static result: settle;
    # measured on the skirt: 250 -> 14.9k-24k iterations, 1000 -> 13.3k, 3000 -> 24k: falls too slowly)
    relax: str = "fire"  # how the drape brings the cloth to rest: "fire" (engine.cloth.solver.FireRelaxer,
    # at fire_damping) or "viscous" (the seeds' viscous damping alone, at drape_damping, which then
    # needs settle_time 0.25 and drape_min 0.5). Measured on the catalogue's five garments in M on
    # default:female and default:male (drape iterations, all ten; every seam, strain and
    # penetration bar still met): viscous ~125k (the dress's hem crept down at ~1 cm/s for 2 s),
    # FIRE 28.5k at fire_damping 100 (34.4k with 0.1 s settle windows), 37.2k at 20 (0.1 s windows)
    fire_damping: float = 100.0  # x the viscous damping while draping with FIRE (200: 1.05 x the
    # iterations, bench_ab --settle 3 at 2 cm, 2026-12-04; within that comparison's spread)
    fire_ramp: float = 0.05  # s: with FIRE, the drape brings gravity from where sewing left it to g
    # over at most this long (FIRE takes the jolt out; at 0.3 the skirt ended 17 mm lower at the
    # hips, another rest on the same body, for 800 more iterations; at 0.02, 1.06 x the iterations,
    # bench_ab --settle 3 at 2 cm, 2026-12-04)
    gravity_ramp: float = 0.3  # s: gravity grows from 0 to g over this long (no jolt when it starts)
    collide_every: int | None = None  # steps between collision checks in both stages (1: every step);
    # None: as sew_check_travel and drape_check_time say. Between checks the reaction force
    # (eq. 16) and K.hold_contacts keep contacts from pressing in, and each check predicts the
    # points as far ahead as the next one (engine.cloth.solver.ClothSolver.step)
    sew_check_travel: float = 0.0015  # m: sewing checks collisions every floor(this / (pull speed
    # cap x dt)) steps, 1 .. SEW_CHECK_MAX (3 at the default 1.5 cm cloth, where the pull moves a
    # point at most 0.44 mm a step; every step at 3 cm) ...
    drape_check_time: float = 0.0004  # s: ... and draping every floor(this / dt) steps, 1 ..
    # DRAPE_CHECK_MAX (2 at 1.5-2 cm, every step at 3 cm). Measured 2026-12-04 (scripts/bench_ab.py
    # --settle 3 --edge-cm 2: the catalogue and the sample skirt, start positions moved by 1 nm,
    # against checks at every step): sewing every 3 and draping every 2, mean iterations 22.2k
    # instead of 25.3k, 0.73 x the wall time (the rounds' own ratios 0.70-0.89), strain max
    # 6.0-6.2 % (5.9-6.0), penetration max 1.0-1.3 mm (0.1-0.8), p99 0, sharp folds at most
    # 10-12 (18-28); sewing and draping every 3: strain max up to 6.4 %; every 4: 6.0 %, but
    # sewing alone at 4 once 6.7 %. At 1.5 cm (the default) all ten catalogue drapes and the
    # sample skirt within every bar (strain max 5.90 %, penetration max 0.4 mm), 28.2k iterations
    # and 9.4 s in all instead of 34.2k and 14.1 s. At 3 cm draping every 2 left default:female's
    # M dress 7 % stretched (tight; 5.8 % at every step), hence the time rule. (Before the strain
    # guard, draping every 2 or 4 steps had left the shirt at 6.1-6.3 %.) With the fallback below,
    # the same comparison: 0.86 x the iterations, strain max 5.91-5.94 %, penetration max 0-1.3 mm.
    tight_every_step: float = 0.01  # draping checks every step from the first settle check (every
    # 0.01 s) after TIGHT_GRACE whose strain max is past the fabric's threshold + this (the strain
    # sewing leaves is worked off first: measured on the dress at 1.63 cm, 6.08 % at 0.01 and
    # 0.02 s, 5.90 % from 0.03 s): there the strain limit and the
    # body fight (a garment too small; cloth wedged between arm and torso), and checks every 2nd step
    # let the cloth into the body (measured before this rule: default:female saved with its arms
    # 30 degrees lower, the shirt and dress dressed with the arms raised and lowered, penetration
    # max 3.1-6.1 mm against 3 allowed; the sample scan's XS sleeveless shirt ended 13 % stretched
    # with 128 sharp folds where checked at every step it is refused at 15-17 %; the scan's L shirt
    # 6.08 %)
    sew_budget: float = 4.0  # s of simulated time
    snap_gap: float = 0.02  # m: when, after snap_after of sewing, the open seams have stopped
    snap_stall: float = 0.5  # s ... closing (the largest gap shrank < 1 mm over this long) and it
    snap_after: float = 2.0  # s ... is within snap_gap (now, and in the median over this long),
    # they are welded where they are; if it stayed wider than snap_gap all that time, sewing
    # gives up then (the error says so), not at the end of sew_budget (measured: the sample
    # scan's XS sleeveless shirt, side seams 2.1-2.3 cm open from ~1 s to the 4 s budget).
    # Measured (default:female,weight=1.0,height=1.45, dress M): one pair of a shoulder seam, the
    # strap pulled tight over the shoulder, stayed 1.1-1.9 cm open from 0.3 s to the 4 s budget
    # (the strain limit takes back the seam's pull) and the whole try-on failed (its armholes
    # now follow its thick arms and it closes; a scan with the arms 20 degrees lower still
    # stalls at 1.3-1.6 cm and is snapped). Without
    # snap_after, 0.25 s windows snapped the sample scan's XL sleeveless shirt at 12.9 mm, which
    # closes by itself in 0.7 s
    drape_budget: float = 6.0  # s of simulated time (the sample skirt and trousers on default:male settle
    # after 3.7-4 s)
    drape_min: float = 0.1  # s: drape at least this long after sewing
    settle_speed: float = 0.005  # m/s: RMS drift of the vertices over a window ...
    strain_guard: float | None = 0.009  # the drape's positions keep springs within the fabric's
    # threshold + this (Provot) where the velocity modification cannot (the body pushing cloth
    # outward), never pulling cloth into the body: measured 6.4 % on two shear springs of the
    # trousers without it; at 0.005 the trousers took twice the iterations to settle
    # (ClothParams.strain_guard, if set, wins)
    too_tight: float = 0.10  # a drape whose strain exceeds the fabric's threshold by this is refused
    refuse_after: float = 2.0  # s: ... early, once it stayed so this long after drape_min. Measured
    # (strain every 0.1 s): the sample scan's L sleeveless shirt, far too small round armholes
    # then cut 1.6 cm shallower (ARMHOLE_PER_ARM_ROOT), 25-44 % from 0.5 s to the end of its 6 s
    # budget; a dress that ends at 6.0 % after a stuck shoulder seam
    # was snapped (default:female,weight=1.0,height=1.45, M) spent 1.3 s at 12-32 % first -- so
    # 0.5 s refused a garment that fits
    observe_every: float = 0.02  # s of simulated time between calls of the observer, if any
    settle_time: float = 0.05  # s: ... of this length, twice in a row, the last at full gravity. With
    # FIRE the cloth comes to rest without the vibration viscous damping leaves (whose amplitude
    # A alone reads as 2 A / window: at 0.1 s a quarter millimetre of it kept viscous dresses and
    # shirts "moving" for the whole budget). Measured against the same drapes run on to 1.5 s
    # and 2 mm/s: nine of the ten catalogue drapes ended 0.2-1.9 mm RMS (1-11 mm at the vertex
    # that moved most, hems and cuffs) from where they came to rest (0.1 s windows: 0.2-1.7 mm,
    # 1-10 mm, for 21 % more iterations); default:male's shirt 8.3 mm (25 mm), its sleeves
    # sliding on at 2-5 mm/s for another 2.4 s


@dataclass
class DrapeResult:
    positions: np.ndarray  # (N, 3) final cloth vertices (sewn)
    triangles: np.ndarray  # (F, 3) int32
    model: ClothModel
    state: ClothState
    iterations: dict
    timing: dict
    seam_gap_max: float
    settled: bool
    kinetic_energy: float
    strain_max: float
    dt: float
    strain_guard: float | None = None  # the drape's guard (threshold + this), None: off
    guard_share: float = 0.0  # share of the last settle window's steps in which the guard acted
    snapped: int = 0  # seam pairs welded by the stall rule (DrapeOptions.snap_gap)
    spec: object = None  # the PatternSpec dressed (set by engine.scene.tryon.run_tryon)
    lowering: dict | None = None  # dressed with the arms raised: the lowering's figures (engine.scene.arms)
    collide_every: dict = field(default_factory=dict)  # steps between collision checks by stage


def _noop(stage: str, fraction: float, message: str) -> None:
    pass


def _check_options(o: DrapeOptions) -> None:
    k = o.collide_every
    if k is not None and not (isinstance(k, (int, np.integer)) and 1 <= k <= 16):
        raise InputError(f"collide_every {k}: check collisions every 1 .. 16 steps")
    if not (0.0 < o.sew_check_travel <= 0.05):
        raise InputError(f"sew_check_travel {o.sew_check_travel} m: use a distance in (0, 0.05]")
    if not (0.0 <= o.tight_every_step <= 1.0):
        raise InputError(f"tight_every_step {o.tight_every_step}: use 0 .. 1 (strain past the fabric's threshold)")
    if not (0.0 < o.drape_check_time <= 0.01):
        raise InputError(f"drape_check_time {o.drape_check_time} s: use a time in (0, 0.01]")


def _sew_every(o: DrapeOptions, dt: float, vmax: float) -> int:
    """Steps between collision checks while sewing: as many as the seam pull (at most vmax)
    takes to move a point sew_check_travel, 1 .. SEW_CHECK_MAX (DrapeOptions.collide_every wins)."""
    return _spacing(o, o.sew_check_travel / max(vmax * dt, 1e-12), SEW_CHECK_MAX)


def _drape_every(o: DrapeOptions, dt: float) -> int:
    """Steps between collision checks while draping: floor(drape_check_time / dt), 1 ..
    DRAPE_CHECK_MAX (DrapeOptions.collide_every wins)."""
    return _spacing(o, o.drape_check_time / dt, DRAPE_CHECK_MAX)


def _spacing(o: DrapeOptions, steps: float, most: int) -> int:
    if o.collide_every is not None:
        return int(o.collide_every)
    return int(min(most, max(1, math.floor(steps))))


def sew_and_drape(garment: Garment, collider: Collider | None, options: DrapeOptions | None = None,
                  progress: Progress = _noop, observer: Observer | None = None) -> DrapeResult:
    """Sew the placed panels, then drape them, against the same collider (module doc)."""
    o = options or DrapeOptions()
    fabric = get_fabric(o.fabric)
    model = build_model(garment.uv, garment.panel, garment.lattice, garment.quads, garment.tris,
                        garment.seams, fabric, _edge(garment), o.params)
    state = ClothState(garment.positions.copy(), np.zeros_like(garment.positions))
    _check_options(o)
    solver = ClothSolver(model, collider, dt=o.dt, force_dt=o.force_dt)
    dt = solver.dt
    solver.collide_every = sew_every = _sew_every(o, dt, o.sew_vmax)
    iters = {"sewing": 0, "draping": 0}
    timing = {"sewing": 0.0, "draping": 0.0}
    cloth_t = {"cloth": 0.0, "collision": 0.0}

    # --- sew ---
    t0 = time.perf_counter()
    pairs = garment.seams.astype(np.int64)
    gap_max = 0.0
    g_sewn = 0.0  # the gravity scale sewing ended with
    snapped = 0
    if len(pairs):
        gaps = np.zeros(len(pairs))
        budget = int(np.ceil(o.sew_budget / dt))
        weld_gap = o.weld_gap if o.weld_gap is not None else 0.5 * _edge(garment)
        gap0 = float(seam_gaps(state.x, pairs, gaps).max())
        far = float(np.median(gaps)) > o.far_gap
        sew_damping = o.far_sew_damping if far else o.sew_damping
        # panels laid out flat (far) whose seams stopped closing are sewn once more from where
        # they were placed, pulled at far_retry_vmax (DrapeOptions)
        pulls = [o.sew_vmax] + ([o.far_retry_vmax] if far and 0.0 < o.far_retry_vmax != o.sew_vmax else [])
        sew_its = 0
        for attempt, vmax in enumerate(pulls):
            if attempt:
                sew_its += solver.iterations
                for k, v in solver.timing.items():
                    cloth_t[k] = cloth_t.get(k, 0.0) + v
                state = ClothState(garment.positions.copy(), np.zeros_like(garment.positions))
                solver = ClothSolver(model, collider, dt=o.dt, force_dt=o.force_dt)
                solver.collide_every = sew_every = _sew_every(o, dt, vmax)
                progress("sewing", 0.0, f"the seams stopped closing: sewing again, pulled at {vmax:g} m/s")
            welded = np.zeros(len(pairs), dtype=np.bool_)
            gap_max, snapped, g_sewn = 0.0, 0, 0.0
            check_every = max(1, int(0.005 / dt))
            observe = max(1, int(o.observe_every / dt))
            tri0 = _triangles(model) if observer is not None else None
            solver.strain_guard = None  # sewing stretches cloth by design; the guard and the strain
            solver.recover = 1e9  # recovery are for the drape (a new solver is made after welding)
            solver.sewing = (pairs, welded, o.sew_tau, vmax)
            # the largest open gaps over two stall windows; with a second pull to come, the
            # windows are retry_stall long and a stall is judged from 2 x retry_stall on, not
            # after snap_after (a flat layout that closes at all closes in 0.1-0.4 s)
            retry = attempt + 1 < len(pulls)
            window = min(o.snap_stall, o.retry_stall) if retry else o.snap_stall
            stall = deque(maxlen=2 * max(1, int(round(window / (check_every * dt)))))
            snap_from = int((min(o.snap_after, 2 * window) if retry else o.snap_after) / dt)
            gave_up = None  # (simulated s, smallest and largest open gap of the last snap_stall) when stuck
            calm = int(round(o.calm_start / dt))
            for it in range(budget):
                g = g_sewn = o.sew_gravity * min(1.0, (it + 1) * dt / o.gravity_ramp)  # let the seams catch first
                solver.step(state, gravity_scale=g, damping_scale=max(sew_damping, o.far_sew_damping) if it < calm
                            else sew_damping, friction_scale=o.sew_friction or 0.0)
                hold_welds(state.x, state.v, model.mass, pairs, welded)
                if observer is not None and it % observe == 0:
                    observer("sewing", state.x, tri0, None)
                if it % check_every == 0:
                    seam_gaps(state.x, pairs, gaps)
                    new = ~welded & (gaps < weld_gap)
                    if new.any():  # the largest gap a weld closed at once (the snap it makes)
                        gap_max = max(gap_max, float(gaps[new].max()))
                    welded |= new
                    _check_finite(state, "sewing")
                    if welded.all():
                        break
                    g = float(gaps[~welded].max())
                    stall.append(g)
                    if len(stall) == stall.maxlen and it >= snap_from:
                        h = len(stall) // 2
                        older, recent = list(stall)[:h], list(stall)[h:]
                        stalled = min(older) - min(recent) < 0.001
                        # (the median: a stalled strap pair on a scan swayed 1.5-2.5 cm for the
                        # whole budget, and the largest never stayed under snap_gap)
                        if stalled and g <= o.snap_gap and np.median(recent) <= o.snap_gap:
                            # stuck: weld the last open pairs where they are (the drape relaxes the
                            # stretch); the snap shows in seam_gap_mm, the count in seam_gap_mm.snapped
                            snapped = int((~welded).sum())
                            gap_max = max(gap_max, g)
                            welded[:] = True
                            break
                        if stalled and min(recent) > o.snap_gap:
                            gave_up = ((it + 1) * dt, min(recent), max(recent))
                            break
                    progress("sewing", min(1.0, 1.0 - g / max(gap0, 1e-9)), f"largest open seam gap {g * 100:.1f} cm")
            seam_gaps(state.x, pairs, gaps)
            if welded.all():
                break
        iters["sewing"] = sew_its + solver.iterations
        if not welded.all():
            open_ids = np.unique(garment.seam_id[~welded])
            worst = {int(s): float(gaps[(garment.seam_id == s) & ~welded].max()) for s in open_ids}
            names = ", ".join(f"{garment.stitch_names[s]} ({g * 100:.1f} cm)" for s, g in
                              sorted(worst.items(), key=lambda kv: -kv[1])[:5])
            when = (f"did not close within {o.sew_budget:.1f} s of simulated time" if gave_up is None else
                    f"stopped closing after {gave_up[0]:.1f} s of simulated time (the widest gap stayed "
                    f"{100 * gave_up[1]:.1f}-{100 * gave_up[2]:.1f} cm for {o.snap_stall:.1f} s)")
            again = f" (sewn twice, pulled at {pulls[0]:g} and {pulls[-1]:g} m/s)" if len(pulls) > 1 else ""
            err = SimulationError(f"sewing {when}{again}; open seams: {names}. The garment may be too small for "
                                  "this body (try a larger size) or the panels start too far apart")
            err.positions, err.triangles = state.x.copy(), _triangles(model)  # for a picture
            err.too_small = True  # (engine.scene.garments.add_size_hint)
            # where the open seams were placed (engine.scene.garments.arms_in_the_way)
            err.open_top = float(garment.positions[pairs[~welded].ravel(), 1].max())
            raise err
        # merge the sewn vertices and continue on the welded model
        vmap = merge_map(model.n, pairs)
        x_new = np.zeros((int(vmap.max()) + 1, 3))
        v_new = np.zeros_like(x_new)
        w = np.zeros(len(x_new))
        np.add.at(x_new, vmap, state.x * model.mass[:, None])
        np.add.at(v_new, vmap, state.v * model.mass[:, None])
        np.add.at(w, vmap, model.mass)
        cloth_t = {k: cloth_t.get(k, 0.0) + v for k, v in solver.timing.items()}
        model = weld_model(model, vmap, garment.uv if o.seam_flexion else None)
        state = ClothState(x_new / w[:, None], v_new / w[:, None])
        # the welded model's own eq. 4 bound (seam points add up their masses and springs: the
        # step may grow, e.g. 0.136 -> 0.148 ms on the dress)
        solver = ClothSolver(model, collider, dt=o.dt, force_dt=o.force_dt)
        dt = solver.dt
    timing["sewing"] = time.perf_counter() - t0
    res = drape(model, state, collider, o, progress, observer, gravity_from=g_sewn, solver=solver)
    timing["draping"] = res.timing["draping"]
    for k in cloth_t:
        cloth_t[k] += res.timing[f"{k}_total"]
    res.iterations = {"sewing": iters["sewing"], "draping": res.iterations["draping"]}
    res.timing = {**timing, **{f"{k}_total": v for k, v in cloth_t.items()}}
    res.seam_gap_max, res.snapped = gap_max, snapped
    if len(pairs):
        res.collide_every = {"sewing": sew_every, **res.collide_every}
    return res


def drape(model: ClothModel, state: ClothState, collider: Collider | None, options: DrapeOptions | None = None,
          progress: Progress = _noop, observer: Observer | None = None, gravity_from: float = 1.0,
          solver: ClothSolver | None = None) -> DrapeResult:
    """The drape stage alone (module doc), from `state` (changed in place) of the sewn `model`:
    until the shape stops moving, or the budget ends; a garment left stretched past the fabric's
    threshold + too_tight is refused. Gravity grows from `gravity_from` x g over the rest of the
    ramp. `solver` (of this model and collider) carries its iteration count and timing on.
    The result's seam fields are zero (no seams are open in a sewn model)."""
    o = options or DrapeOptions()
    fabric = get_fabric(o.fabric)
    _check_options(o)
    if solver is None:
        solver = ClothSolver(model, collider, dt=o.dt, force_dt=o.force_dt)
    dt = solver.dt
    solver.collide_every = every = _drape_every(o, dt)
    t0 = time.perf_counter()
    it0 = solver.iterations
    timing0 = dict(solver.timing)
    if o.params.strain_guard is None:
        solver.strain_guard = o.strain_guard
    solver.recover = o.params.recover
    budget = int(np.ceil(o.drape_budget / dt))
    min_it = int(np.ceil(o.drape_min / dt))
    # the settle test runs every 1/SETTLE_CHECKS of a window, on the two windows just ended
    sub = max(1, int(np.ceil(o.settle_time / dt / SETTLE_CHECKS)))
    window = sub * SETTLE_CHECKS
    check_every = max(1, int(0.005 / dt))
    observe = max(1, int(o.observe_every / dt))
    tri1 = _triangles(model) if observer is not None else None
    settled = False
    snaps = deque([state.x.copy()], maxlen=2 * SETTLE_CHECKS + 1)  # positions every `sub` steps
    guards = deque(maxlen=SETTLE_CHECKS)  # steps of each sub-window in which the strain guard acted
    strains = deque(maxlen=max(1, int(round(o.refuse_after / (sub * dt)))))  # max strain at the last checks
    refuse = fabric.strain_threshold + o.too_tight
    tight = fabric.strain_threshold + o.tight_every_step
    every_step_from = None
    drift, guard_steps, guard_share = np.inf, 0, 0.0
    if o.relax not in ("fire", "viscous"):
        raise InputError(f"unknown relaxation '{o.relax}': use fire or viscous")
    fire = FireRelaxer() if o.relax == "fire" else None
    damping = o.fire_damping if fire is not None else o.drape_damping
    ramp = o.gravity_ramp if fire is None else min(o.gravity_ramp, o.fire_ramp)
    for it in range(budget):
        # gravity goes on growing from where sewing left it (no second ramp from zero)
        solver.step(state, gravity_scale=min(1.0, gravity_from + (it + 1) * dt / ramp),
                    damping_scale=damping)
        if fire is not None:
            fire.after_step(solver, state)
        guard_steps += solver.guarded > 0
        if observer is not None and it % observe == 0:
            observer("draping", state.x, tri1, None)
        if it % check_every == 0:
            _check_finite(state, "draping")
            progress("draping", _settle_fraction(drift, o.settle_speed),
                     f"drift {drift * 100:.2f} cm/s (at rest below {o.settle_speed * 100:.1f})")
        if (it + 1) % sub == 0:
            snaps.append(state.x.copy())
            guards.append(guard_steps)
            guard_steps = 0
            # A garment too small for the body stays stretched far past the limit (drapes that
            # fit mostly stay at threshold + 0.6-0.9 %, the strain guard holds them there):
            # refuse it once it has been so for refuse_after, not after the whole budget
            strains.append(solver.max_strain(state))
            if (solver.collide_every > 1 and strains[-1] > tight and (it + 1) * dt > TIGHT_GRACE
                    and o.collide_every is None):
                # stretched past what the strain guard holds: the strain limit and the body are
                # fighting (a garment too small, cloth wedged between arm and torso) -- they
                # alternate at every step from here on (DrapeOptions.tight_every_step)
                solver.collide_every = 1
                every_step_from = it + 1
            if it >= min_it and len(strains) == strains.maxlen and min(strains) > refuse:
                raise _too_small(state, model, min(strains), fabric,
                                 f"for {len(strains) * sub * dt:.1f} s of draping it stayed stretched at least")
            if len(snaps) == snaps.maxlen:
                # settled = the shape stopped moving: RMS displacement over each of the last two
                # windows, as a speed (contacts keep a jitter of a few mm/s in the velocities that
                # goes nowhere)
                older = _rms_move(snaps[SETTLE_CHECKS], snaps[0]) / (window * dt)
                drift = _rms_move(snaps[-1], snaps[SETTLE_CHECKS]) / (window * dt)
                guard_share = sum(guards) / window
                full = gravity_from + (it + 1 - window) * dt / ramp >= 1.0  # the last window at full g
                if max(older, drift) < o.settle_speed and it >= min_it and full:
                    settled = True
                    break
    strain = solver.max_strain(state)
    if strain > refuse:
        raise _too_small(state, model, strain, fabric, "after draping it is stretched")
    return DrapeResult(positions=state.x.copy(), triangles=_triangles(model), model=model, state=state,
                       iterations={"draping": solver.iterations - it0},
                       timing={"draping": time.perf_counter() - t0,
                               **{f"{k}_total": solver.timing[k] - timing0.get(k, 0.0) for k in solver.timing}},
                       seam_gap_max=0.0, settled=settled, kinetic_energy=solver.kinetic_energy(state),
                       strain_max=strain, dt=dt, strain_guard=solver.strain_guard,
                       guard_share=guard_share, snapped=0,
                       collide_every={"draping": int(every), **({"every_step_from_s": every_step_from * dt}
                                                                if every_step_from is not None else {})})


def _settle_fraction(drift: float, settle_speed: float, start: float = 1.0) -> float:
    """The drape's progress for a progress bar: how far the drift has come down from `start`
    (m/s) to the settle speed, on a log scale (its end cannot be known in advance; a bar that
    counted simulated time filled long before the cloth came to rest)."""
    if not np.isfinite(drift) or drift >= start:
        return 0.0
    return float(min(1.0, np.log(start / max(drift, settle_speed)) / np.log(start / settle_speed)))


def _edge(g: Garment) -> float:
    """The garment's grid spacing (from its quads), used for flexion stiffness."""
    if len(g.quads):
        q = g.uv[g.quads]
        return float(np.median(np.linalg.norm(q[:, 1] - q[:, 0], axis=1)))
    t = g.uv[g.tris]
    return float(np.median(np.linalg.norm(t[:, 1] - t[:, 0], axis=1)))


def most_stretched(x: np.ndarray, model: ClothModel) -> tuple[float, np.ndarray]:
    """(strain, midpoint (3,)) of the most stretched structural or shear spring."""
    s = model.springs[model.kind != FLEXION]
    r = model.rest[model.kind != FLEXION]
    a, b = x[s[:, 0]], x[s[:, 1]]
    k = int(np.argmax(np.linalg.norm(b - a, axis=1) / r))
    return float(np.linalg.norm(b[k] - a[k]) / r[k] - 1.0), 0.5 * (a[k] + b[k])


def _too_small(state: ClothState, model: ClothModel, strain: float, fabric, how: str) -> SimulationError:
    err = SimulationError(f"the garment is too small for this body: {how} {100 * strain:.0f} % where "
                          f"{fabric.name} allows {100 * fabric.strain_threshold:.0f} %; try a larger size")
    err.positions, err.triangles = state.x.copy(), _triangles(model)  # for a picture
    err.too_small = True  # (engine.scene.garments)
    err.stretched_at = most_stretched(state.x, model)[1]  # (engine.scene.garments.arms_in_the_way)
    return err


def _triangles(m: ClothModel) -> np.ndarray:
    q = m.quads
    return np.concatenate([m.tris, q[:, [0, 1, 2]], q[:, [0, 2, 3]]]).astype(np.int32)


def _rms_move(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


def _check_finite(state: ClothState, stage: str) -> None:
    if not (np.all(np.isfinite(state.x)) and np.all(np.isfinite(state.v))):
        raise SimulationError(f"the cloth became unstable while {stage} (non-finite positions); "
                              "use a smaller time step or a softer fabric")
    if state.x[:, 1].max() < FELL_BELOW:
        raise SimulationError(f"the garment fell off the body while {stage} (all of it below the feet): it is far "
                              "too large for this body, or its pattern places it away from the body; try a "
                              "smaller size, or check the panels' translation")
    if np.abs(state.x).max() > 100.0:
        raise SimulationError(f"the cloth flew off while {stage} (a vertex is more than 100 m away); "
                              "use a smaller time step")
