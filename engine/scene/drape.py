"""Dress a standing body (seed 003 end to end): sew the placed panels, then drape.

Stages end on measured conditions within a bounded budget of simulated time (engine.scene.tuning
holds their constants):
- sew: friction off (the panels slide over the body into place), gravity ramped in so the seams
  catch before the panels fall; each open stitch pair is pulled shut (a velocity modification,
  after the strain limit and before the collision response); a pair closer than the weld gap is
  welded (moves as one point); when every pair is welded the sewn vertices are merged, with
  bending springs across the seams. Panels laid out far apart (GarmentCode's flat layout) are
  sewn at the drape's damping, and sewn once more, pulled slower, if their seams stop closing.
  Seams that stop closing a little open are welded where they are; wider, sewing gives up and
  SimulationError names the seams that stayed open and their gaps.
- drape: gravity (still growing where sewing ended), the cloth brought to rest by FIRE
  (engine.cloth.solver.FireRelaxer) rather than heavy viscous damping, until its shape stops
  moving: the RMS vertex drift over each of the last two windows below the settle speed (tested
  every 1/SETTLE_CHECKS of a window). A garment left stretched far past the fabric's strain
  threshold is refused as too small (SimulationError), early when it stays so.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Callable

import numpy as np

from engine.cloth.config import Attachment, Control, Sewing, StepConfig
from engine.cloth.fabrics import FABRICS, get_fabric
from engine.cloth.model import ClothModel, ClothState, build_model, spring_strains, weld_model, with_elastic
from engine.cloth.solver import ClothSolver, FireRelaxer
from engine.cloth.welds import hold_welds, merge_map, seam_gaps
from engine.collide.base import Collider
from engine.errors import SimulationError, TimeLimitError
from engine.garment.garment import Garment
from engine.scene.request import TryOnOptions
from engine.scene.attach import welded
from engine.scene.girth import girth_words, part_girths
from engine.scene.layers import needs_self_contact
from engine.scene.tuning import Tuning

if TYPE_CHECKING:  # (the map collider's module loads OpenGL: not at import)
    from engine.collide.collider import PassThrough

FELL_BELOW = -0.05  # m: cloth wholly below this height has fallen off the body (feet stand on y = 0) ...
FELL_ON_FLOOR = 0.10  # m: ... or, over a ground, wholly within this of it (a heap on the floor)
SETTLE_CHECKS = 5  # the settle test runs this many times a window (on the two windows just ended)
MEET_STEPS = 12  # steps out of the body from a seam pair's midpoint (_meet_beside) ...
MEET_EVERY = 4  # ... taken every this many gap checks (the body and the cloth move little between)
GAP_CHECK = 0.005  # s: how often sewing measures its seams' gaps (and progress is reported)
Progress = Callable[[str, float, str], None]  # (stage, fraction 0..1, message)
# (stage, cloth positions (N, 3), triangles (F, 3), body vertices (M, 3) or None when unchanged):
# called every Tuning.observe_every s of simulated time, e.g. to stream the cloth to a viewer
Observer = Callable[[str, np.ndarray, np.ndarray, "np.ndarray | None"], None]


def time_limited(progress: Progress | None, seconds: float, whose: str) -> Progress:
    """`progress` (or none) that raises TimeLimitError once `seconds` of wall time have passed
    since it was made: sewing and draping report progress every few milliseconds of simulated
    time, so a try-on stops within a step or two of its limit (never a run that goes on for a
    quarter of an hour on a seam that will not close). `whose`: whose limit it is, for the message."""
    end, last = time.monotonic() + seconds, ["starting"]

    def limited(stage: str, fraction: float, message: str) -> None:
        if time.monotonic() > end:
            raise TimeLimitError(
                f"stopped after {seconds:g} s ({whose}) while still {stage} ({last[0]}): a pattern this slow "
                "to sew and drape usually has a part cut too small for the body or seams that do not close; "
                "a coarser cloth (a larger --resolution, resolution_cm) drapes faster")
        last[0] = message or stage
        if progress is not None:
            progress(stage, fraction, message)

    return limited


def dressing_config(request: TryOnOptions, tuning: Tuning, layered: bool = False) -> StepConfig:
    """The solver's step configuration for sewing and draping; layered: with cloth-cloth contact
    (engine.scene.layers decides; DrapeTuning.self_contact "on" forces it)."""
    on = tuning.drape.self_contact == "on" or (layered and tuning.drape.self_contact == "auto")
    step = replace(tuning.drape.step, velocity_mode=request.velocity_mode)
    d = tuning.drape
    if step.strain_guard is not None and d.soft_guard is not None and \
            get_fabric(request.fabric).strain_threshold >= d.soft_from:
        step = replace(step, strain_guard=min(step.strain_guard, d.soft_guard))
    return replace(step, self_collision=True) if on else step


@dataclass(frozen=True)
class Around:
    """What a drape meets besides its collider. floor: the ground's height (m; Control.floor), or
    None. body: the body's MeshBVH, or None: where FIRE settles with cloth standing out from it
    (standing_out, DrapeTuning.stand_out), the cloth away from it is let fall until it hangs, then
    settles with FIRE again."""

    floor: float | None = None
    body: object = None


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
    snapped: int = 0  # seam pairs welded by the stall rule (SewTuning.snap_gap)
    spec: object = None  # the PatternSpec dressed (set by engine.scene.tryon.run_tryon)
    lowering: dict | None = None  # dressed with the arms raised: the lowering's figures (engine.scene.arms)
    released: bool | None = None  # cloth passed through parts of the body (drape's release): whether the
    # whole body took over at a settle (False: the drape never settled); None: nothing passed through
    collide_every: dict = field(default_factory=dict)  # steps between collision checks by stage
    self_contact: tuple[bool, str] = (False, "")  # cloth-cloth contact: on, and why (engine.scene.layers)
    vertex_map: np.ndarray | None = None  # (N unsewn,) each garment vertex's index in positions (None: not sewn)
    finish: dict | None = None  # settled again against the body's mesh (_finish_exact), or None
    held: list[str] = field(default_factory=list)  # panels the strain limit holds at it over a tenth (held_panels)
    lowered: tuple | None = None  # placed lower for a short rise (engine.scene.tryon._crotch_drop's), or None
    # FIRE settled with cloth standing out from the body (drape's around.body): {share, at_s, viscous_s}, or None
    stood_out: dict | None = None


def _noop(stage: str, fraction: float, message: str) -> None:
    pass


def _spacing(tuning: Tuning, steps: float, most: int) -> int:
    """Steps between collision checks: `steps` rounded down, 1 .. most (Tuning.collide_every wins)."""
    if tuning.collide_every is not None:
        return int(tuning.collide_every)
    return int(min(most, max(1, math.floor(steps))))


def _sew_every(tuning: Tuning, dt: float, vmax: float) -> int:
    """While sewing: as many steps as the seam pull (at most vmax) takes to move a point check_travel."""
    return _spacing(tuning, tuning.sew.check_travel / max(vmax * dt, 1e-12), tuning.sew.max_check_every)


def _drape_every(tuning: Tuning, dt: float) -> int:
    """While draping: floor(check_time / dt) steps."""
    return _spacing(tuning, tuning.drape.check_time / dt, tuning.drape.max_check_every)


@dataclass
class _Dressing:
    """What sewing and draping share: the garment, the body, the user's options and the tuning."""

    garment: Garment
    collider: Collider | None
    request: TryOnOptions
    tuning: Tuning
    progress: Progress
    observer: Observer | None
    attachment: Attachment | None = None  # labelled edges held while sewing (engine.scene.attach)
    layered: bool = False  # with cloth-cloth contact (engine.scene.layers)
    body: object = None  # the body's MeshBVH (seam pairs meeting beside it, SewTuning.meet_outside), or None
    pass_through: PassThrough | None = None  # parts of the body some cloth passes through until it hangs
    # (body vertices,) bool x 2: the arms hanging apart from the trunk (engine.body.hanging), and
    # those arms whole from under the armpits; or None
    arms: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def exempt(self) -> np.ndarray | None:
        """(N unsewn,) the garment's vertices that pass through parts of the body, or None."""
        return None if self.pass_through is None else self.pass_through.vertices

    @cached_property
    def meet_side(self) -> np.ndarray:
        """(P, 3) each stitch pair's way out of the body (_meet_beside): from the middles of the two
        panels to the pair's ends, as placed, square to each edge where it is (the part along the
        edge is left out: a sleeve's underarm seam ends at the armpit, far along the sleeve from
        its middle, and would otherwise be sent through the torso rather than under the arm)."""
        g = self.garment
        n = int(g.panel.max()) + 1
        c = np.zeros((n, 3))
        np.add.at(c, g.panel, g.positions)
        c /= np.maximum(np.bincount(g.panel, minlength=n), 1)[:, None]
        # each pair's neighbours along its stitch (the pairs of a stitch follow its edges in order)
        k = np.arange(len(g.seams))
        prev = np.where((k > 0) & (np.roll(g.seam_id, 1) == g.seam_id), k - 1, k)
        nxt = np.where((k < len(k) - 1) & (np.roll(g.seam_id, -1) == g.seam_id), k + 1, k)
        side = np.zeros((len(k), 3))
        for v in (g.seams[:, 0], g.seams[:, 1]):
            out = g.positions[v] - c[g.panel[v]]
            t = g.positions[v[nxt]] - g.positions[v[prev]]
            t /= np.maximum(np.linalg.norm(t, axis=1), 1e-12)[:, None]
            side += out - (out * t).sum(1)[:, None] * t
        return side

    @cached_property
    def beside_arm(self) -> np.ndarray | None:
        """(P,) bool: the stitch pairs of panels that lie, as placed, over the trunk (most of each
        panel's cloth nearest a body vertex off the arms), or None without arms: where such a
        pair's path runs through a hanging arm, the arm is outside the garment (it leaves by an
        armhole above), and the pair meets on the trunk's side of it (_meet_beside)."""
        if self.arms is None or self.body is None or not len(self.garment.seams):
            return None
        from scipy.spatial import cKDTree

        g = self.garment
        n = int(g.panel.max()) + 1
        near_arm = self.arms[1][cKDTree(self.body.verts).query(g.positions)[1]]
        share = np.bincount(g.panel, weights=near_arm, minlength=n) / np.maximum(np.bincount(g.panel, minlength=n), 1)
        return ~(share[g.panel[g.seams]] >= 0.5).any(axis=1)

    @cached_property
    def body_axis(self) -> tuple[float, float]:
        """(x, z) of the body's vertical axis: the median of its vertices off the hanging arms."""
        v = self.body.verts if self.arms is None else self.body.verts[~self.arms[1]]
        return float(np.median(v[:, 0])), float(np.median(v[:, 2]))

    def solver(self, model: ClothModel, exempt: np.ndarray | None = None) -> ClothSolver:
        """A solver of `model` against the body; exempt: the model's vertices that pass through
        the parts of the body that pass_through leaves out."""
        body = self.collider
        if exempt is not None and self.pass_through is not None:
            body = self.pass_through.collider(body, exempt, model.quads, model.tris)
        return ClothSolver(model, body, dressing_config(self.request, self.tuning, self.layered),
                           dt=self.request.dt, force_dt=self.request.force_dt)

    def fresh_state(self) -> ClothState:
        return ClothState(self.garment.positions.copy(), np.zeros_like(self.garment.positions))


@dataclass
class _Sewn:
    """Sewing's outcome: the welded model, its state and solver, and the figures of the stage."""

    model: ClothModel
    state: ClothState
    solver: ClothSolver
    iterations: int
    timing: dict  # cloth and collision seconds of the sewing solvers
    gap_max: float  # the largest gap a weld closed at once
    snapped: int  # pairs welded where they stuck
    gravity: float  # the gravity scale sewing ended with
    every: int  # steps between collision checks
    attachment: Attachment | None  # on the welded cloth
    vertex_map: np.ndarray  # (N unsewn,) -> welded vertex
    exempt: np.ndarray | None = None  # (N welded,) the vertices that pass through (_Dressing.pass_through)


FLOOR_BELOW = 0.01  # m: the ground under the body's soles (ground)


def ground(body_vertices: np.ndarray) -> float:
    """The height the cloth rests on at the body's feet (Control.floor; a gown longer than the
    body is tall lies on the floor): FLOOR_BELOW under the soles -- cloth the body pushes out
    through a sole (a hem round the feet) ends between foot and floor instead of being fought
    over (a ground above the soles pushed it back into the feet: 177 % strain)."""
    return float(body_vertices[:, 1].min()) - FLOOR_BELOW


def sew_and_drape(garment: Garment, collider: Collider | None, request: TryOnOptions = TryOnOptions(),
                  tuning: Tuning = Tuning(), progress: Progress = _noop, observer: Observer | None = None,
                  attachment: Attachment | None = None, body_bvh=None,
                  pass_through: PassThrough | None = None, floor: float | None = None,
                  panel_fabrics: dict[str, str] | None = None, arms: tuple | None = None) -> DrapeResult:
    """Sew the placed panels, then drape them, against the same collider (module doc). attachment:
    vertices held on planes while sewing and draping (engine.scene.attach). body_bvh: the body's
    MeshBVH (engine.collide.bvh), for seam pairs whose path runs through the body (None: not).
    pass_through: cloth that passes through parts of the body while it is sewn and until the drape
    first settles (then it meets the whole body, and settles again where the parts caught it).
    floor: the ground's height (m): cloth rests on it while draping (Control.floor; None: no
    ground). Not while sewing: GarmentCode stacks a jumpsuit's trousers below its bodice in the flat
    layout, under the feet, and they rise into place as they are sewn (held up by the ground at
    1 m/s instead, f_smpl 2_003's ended 17 % stretched in jersey; it drapes in cotton at 5.5 %).
    panel_fabrics: panel name -> the fabric it is sewn from where not the request's (build_model).
    arms: ((body vertices,) bool x 2) the arms hanging apart from the trunk, and those arms whole
    (engine.body.hanging.hanging_arms; with body_bvh): a trunk panel's seam caught round one
    closes between it and the trunk.
    A garment refused as too small (in sewing or draping) names on the error, as tight_panels, the
    panels that were held past their limit (_too_small_panels, held_panels); a drape names them in
    DrapeResult.held."""
    tuning.validate()
    layered = needs_self_contact(garment, tuning)
    job = _Dressing(garment, collider, request, tuning, progress, observer, attachment, layered[0], body_bvh,
                    pass_through, arms)
    names = {n: i for i, n in enumerate(garment.panel_names)}
    model = build_model(garment.uv, garment.panel, garment.lattice, garment.quads, garment.tris, garment.seams,
                        get_fabric(request.fabric), _edge(garment), tuning.cloth,
                        panel_fabrics={names[n]: get_fabric(f) for n, f in (panel_fabrics or {}).items() if n in names})
    if attachment is not None and attachment.elastic is not None:  # (a held top gathered onto an elastic)
        model = with_elastic(model, attachment.elastic.vertices, attachment.elastic.factor)
    state = job.fresh_state()
    exempt = pass_through.vertices if pass_through is not None else None
    solver = job.solver(model, exempt)
    t0 = time.perf_counter()
    sewn = _sew(job, model, state, solver) if len(garment.seams) else None
    t_sew = time.perf_counter() - t0
    if sewn is not None:
        model, state, solver, exempt = sewn.model, sewn.state, sewn.solver, sewn.exempt
    vmap = sewn.vertex_map if sewn is not None else None
    guard = dressing_config(request, tuning, layered[0]).strain_guard or 0.0
    try:
        res = drape(model, state, collider, request, tuning, progress, observer,
                    gravity_from=sewn.gravity if sewn else 0.0, solver=solver,
                    attachment=sewn.attachment if sewn else attachment,
                    release=None if exempt is None else (pass_through, exempt), around=Around(floor, body_bvh))
    except SimulationError as e:
        if getattr(e, "stretched_at", None) is not None:  # (too small: which parts, and how far round)
            e.tight_panels = held_panels(garment, model, e.positions, vmap, get_fabric(request.fabric), guard)
            words = _round_words(job, e.positions[vmap] if vmap is not None else e.positions, e.tight_panels)
            msg, tail = str(e), "; try a larger size"
            if words and msg.endswith(tail):
                e.args = (msg[:-len(tail)] + words + tail,) + tuple(e.args[1:])
        raise
    if body_bvh is not None and request.collision == "image" and tuning.drape.finish_pen is not None:
        res = _finish_exact(job, res, solver, sewn.attachment if sewn else attachment, floor)
    cloth_t = dict(sewn.timing) if sewn else {"cloth": 0.0, "collision": 0.0}
    for k in cloth_t:
        cloth_t[k] += res.timing[f"{k}_total"]
    res.iterations = {"sewing": sewn.iterations if sewn else 0, "draping": res.iterations["draping"]}
    res.timing = {"sewing": t_sew if sewn else 0.0, "draping": res.timing["draping"],
                  **{f"{k}_total": v for k, v in cloth_t.items()}}
    if sewn is not None:
        res.seam_gap_max, res.snapped = sewn.gap_max, sewn.snapped
        res.collide_every = {"sewing": sewn.every, **res.collide_every}
        res.vertex_map = sewn.vertex_map
    res.self_contact = layered
    if res.strain_max > get_fabric(request.fabric).strain_threshold + guard:
        res.held = held_panels(garment, res.model, res.positions, vmap, get_fabric(request.fabric), guard)
    return res


HELD_AT = 0.8  # x the strain guard: a spring past its fabric's threshold by this much is held at its limit ...
HELD_SHARE = 0.10  # ... and a panel with this share of its springs so held is held (held_panels)


def held_panels(garment: Garment, model: ClothModel, x: np.ndarray, vertex_map: np.ndarray | None,
                fabric, guard: float) -> list[str]:
    """The panels the strain limit holds at it over HELD_SHARE of their springs or more (the
    guard holds a spring at threshold + guard): a part smaller round than the body where it sits.
    On GarmentCode's shirt mean_female 53_009 given up in cotton, its four cuffs (20-25 % of
    their springs held) and not its sleeves (at most 2 %), although the most stretched springs
    (75 %) lay in a sleeve beside the gathered seam into its cuff. x: the model's positions (sewn:
    vertex_map, the garment's vertices -> the model's; None: not sewn)."""
    panel = np.full(model.n, -1, dtype=np.int64)
    if vertex_map is None:
        panel[:] = garment.panel
    else:
        panel[vertex_map] = garment.panel  # (a sewn vertex: one of its panels)
    s, strain = spring_strains(model, x)
    p0, p1 = panel[s[:, 0]], panel[s[:, 1]]
    inner = (p0 == p1) & (p0 >= 0)
    n = np.bincount(p0[inner], minlength=len(garment.panel_names))
    held = np.bincount(p0[inner], weights=strain[inner] > fabric.strain_threshold + HELD_AT * guard,
                       minlength=len(garment.panel_names))
    return [garment.panel_names[p] for p in np.flatnonzero((n >= 10) & (held >= HELD_SHARE * np.maximum(n, 1)))]


def _sew(job: _Dressing, model: ClothModel, state: ClothState, solver: ClothSolver) -> _Sewn:
    """Sew every stitch pair shut (module doc), once more pulled slower when a flat layout's seams
    stopped closing (not beside a part too small round the body); then merge the sewn vertices.
    Raises SimulationError when seams stay open."""
    t = job.tuning.sew
    garment, dt = job.garment, solver.dt
    pairs = garment.seams.astype(np.int64)
    gaps = np.zeros(len(pairs))
    gap0 = float(seam_gaps(state.x, pairs, gaps).max())
    far = float(np.percentile(gaps, 90)) > t.far_gap  # (a dart's pairs start closed in any layout)
    pulls = [t.vmax] + ([t.far_retry_vmax] if far and 0.0 < t.far_retry_vmax != t.vmax else [])
    its, timing = 0, {"cloth": 0.0, "collision": 0.0}
    for attempt, vmax in enumerate(pulls):
        if attempt:
            its += solver.iterations
            for k, v in solver.timing.items():
                timing[k] += v
            state, solver = job.fresh_state(), job.solver(model, job.exempt)
            job.progress("sewing", 0.0, f"the seams stopped closing: sewing again, pulled at {vmax:g} m/s")
        control = Control(friction_scale=t.friction or 0.0, collide_every=_sew_every(job.tuning, dt, vmax),
                          sewing=Sewing(pairs, np.zeros(len(pairs), dtype=np.bool_), t.tau, vmax,
                                        panel=garment.panel.astype(np.int64) if far else None,
                                        panel_damping=t.far_panel_damping,
                                        **(_meeting(len(pairs)) if far and t.meet_outside and job.body is not None
                                           else {})),
                          attachment=job.attachment)
        pull = _pull(job, model, state, solver, control, far, retry=attempt + 1 < len(pulls), gap0=gap0)
        if pull.welded.all():
            break
        if attempt + 1 < len(pulls) and _too_small_panels(job, model, state, pull.welded) is not None:
            # (stalled beside cloth stretched far past the fabric: a part too small round the body,
            # which no slower pull closes -- each pull is 2-3 s of simulated time)
            pulls = pulls[:attempt + 1]
            break
    its += solver.iterations
    if not pull.welded.all():
        raise _open_seams(job, model, state, pull, pulls)
    for k, v in solver.timing.items():
        timing[k] += v
    # merge the sewn vertices and go on with the welded model (at its own eq. 4 bound)
    vmap = merge_map(model.n, pairs)
    x_new = np.zeros((int(vmap.max()) + 1, 3))
    v_new = np.zeros_like(x_new)
    w = np.zeros(len(x_new))
    np.add.at(x_new, vmap, state.x * model.mass[:, None])
    np.add.at(v_new, vmap, state.v * model.mass[:, None])
    np.add.at(w, vmap, model.mass)
    model = weld_model(model, vmap, garment.uv if t.seam_flexion else None)
    state = ClothState(x_new / w[:, None], v_new / w[:, None])
    exempt = None
    if job.exempt is not None:  # a welded vertex passes through while all its copies do
        exempt = np.ones(len(x_new), dtype=bool)
        np.logical_and.at(exempt, vmap, job.exempt)
    return _Sewn(model=model, state=state, solver=job.solver(model, exempt), iterations=its, timing=timing,
                 gap_max=pull.gap_max, snapped=pull.snapped, gravity=pull.gravity, every=int(control.collide_every),
                 attachment=welded(job.attachment, vmap), vertex_map=vmap, exempt=exempt)


@dataclass
class _Pull:
    """One pull of the seams: which pairs were welded, the gaps last measured, and the figures."""

    welded: np.ndarray
    gaps: np.ndarray
    gap_max: float = 0.0
    snapped: int = 0
    gravity: float = 0.0
    gave_up: tuple | None = None  # (simulated s, smallest and largest open gap of the last snap_stall)


def _pull(job: _Dressing, model: ClothModel, state: ClothState, solver: ClothSolver, control: Control, far: bool,
          retry: bool, gap0: float) -> _Pull:
    """Sew until every pair is welded, the seams stall, or the budget ends. With a retry to come,
    a stall is judged over retry_stall windows from 2 x retry_stall on (a flat layout that closes
    at all closes in 0.1-0.4 s), not after snap_after."""
    t, dt = job.tuning.sew, solver.dt
    sewing = control.sewing
    pairs, welded = sewing.pairs, sewing.welded
    out = _Pull(welded=welded, gaps=np.zeros(len(pairs)))
    damping = t.far_damping if far else t.damping
    check_every = max(1, int(GAP_CHECK / dt))
    observe = max(1, int(job.tuning.observe_every / dt))
    tri0 = _triangles(model) if job.observer is not None else None
    weld_gap = t.weld_gap if t.weld_gap is not None else 0.5 * _edge(job.garment)
    window = min(t.snap_stall, t.retry_stall) if retry else t.snap_stall
    stall = deque(maxlen=2 * max(1, int(round(window / (check_every * dt)))))
    snap_from = int((min(t.snap_after, 2 * window) if retry else t.snap_after) / dt)
    give_from = int(2 * window / dt)  # (a stall wider than snap_gap: judged from two windows on)
    calm = int(round(t.calm_start / dt))
    # a flat layout sews with gravity growing as its seams close (else it falls off the body
    # before they close round it): the share of the 90th-percentile gap closed, squared
    p90_0 = float(np.percentile(seam_gaps(state.x, pairs, out.gaps), 90)) if far else 0.0
    closed = 0.0 if far else 1.0
    for it in range(int(np.ceil(t.budget / dt))):
        control.gravity_scale = out.gravity = t.gravity * min(1.0, (it + 1) * dt / t.gravity_ramp) * closed ** 2
        control.damping_scale = max(damping, t.far_damping) if it < calm else damping
        solver.step(state, control)
        hold_welds(state.x, state.v, model.mass, pairs, welded)
        if job.observer is not None and it % observe == 0:
            job.observer("sewing", state.x, tri0, None)
        if it % check_every:
            continue
        seam_gaps(state.x, pairs, out.gaps)
        if far:
            closed = max(closed, min(1.0, 1.0 - float(np.percentile(out.gaps, 90)) / max(p90_0, 1e-9)))
        if sewing.meet is not None and (it // check_every) % MEET_EVERY == 0:
            _meet_beside(job, state.x, sewing, out.gaps, weld_gap)
        new = ~welded & (out.gaps < weld_gap)
        if new.any():  # the largest gap a weld closed at once (the snap it makes)
            out.gap_max = max(out.gap_max, float(out.gaps[new].max()))
        welded |= new
        _check_finite(state, "sewing")
        if welded.all():
            break
        g = float(out.gaps[~welded].max())
        if far and t.far_together:
            # every open pair closes in the time the widest one needs: a dart or waist seam shut
            # at once crumpled a fitted bodice while its shoulder seams were still 55 cm apart
            control.sewing = sewing = replace(sewing, tau=max(t.tau, g / sewing.vmax))
        stall.append(g)
        # (a stall wider than snap_gap gives up from give_from on; one within it is welded from
        # snap_from on: it may yet close by itself)
        if len(stall) == stall.maxlen and it >= give_from and \
                _stalled(out, stall, it, dt, t, _lone_outside(job, state.x, pairs, welded), snap=it >= snap_from):
            break
        job.progress("sewing", min(1.0, 1.0 - g / max(gap0, 1e-9)), f"largest open seam gap {g * 100:.1f} cm")
    seam_gaps(state.x, pairs, out.gaps)
    return out


def _meeting(n: int) -> dict:
    return {"meet": np.zeros((n, 3)), "meet_on": np.zeros(n, dtype=np.bool_)}


def _meet_beside(job: _Dressing, x: np.ndarray, sewing: Sewing, gaps: np.ndarray, weld_gap: float) -> None:
    """Open pairs whose midpoint lies inside the body (their straight path runs through it: a leg
    or a shoulder between the two ends) meet just outside the body on the side their edges lie
    on: sewing.meet/meet_on set in place. From the midpoint, the way out is the direction from the
    two panels' middles to the pair's ends as placed, square to their edges (_Dressing.meet_side:
    an inseam lies on the inner side of its leg's panels, a side seam at the side of the torso's, a
    shoulder seam at the top), square to the gap; the surface is found by stepping along it by the
    distance to the body. Where no surface is found that way within the pair's gap (the way out
    crossed the body), the pair meets at the surface nearest its midpoint. A pair that
    straddles a limb is otherwise pulled straight into it from both sides and stalls there, or
    goes round the wrong side (a trouser leg twisted round its leg)."""
    on = np.flatnonzero(~sewing.welded & (gaps > 2.0 * weld_gap))
    sewing.meet_on[:] = False
    if not len(on):
        return
    a, b = sewing.pairs[on, 0], sewing.pairs[on, 1]
    mid = 0.5 * (x[a] + x[b])
    sd = job.body.signed_distance(mid, max_distance=0.5)
    inside = np.isfinite(sd) & (sd < 0.0)
    if not inside.any():
        return
    on, a, b, mid, sd = on[inside], a[inside], b[inside], mid[inside], sd[inside]
    gap = x[b] - x[a]
    u = gap / np.maximum(np.linalg.norm(gap, axis=1), 1e-12)[:, None]
    d = job.meet_side[on]
    if job.beside_arm is not None and job.beside_arm[on].any():
        # a trunk panel's pair caught round a hanging arm (a wide tunic's side seam under its
        # armhole, the arm hanging through the gap): it meets between the arm and the trunk, the
        # way towards the body's axis -- round the arm's outer side it stalled, the arm inside
        _, _, _, face, _ = job.body.closest(mid)
        caught = job.beside_arm[on] & (face >= 0)
        caught[caught] = job.arms[0][job.body.faces[face[caught], 0]]
        if caught.any():
            axis = np.asarray(job.body_axis)
            d = d.copy()
            d[caught] = 0.0
            d[caught, 0] = axis[0] - mid[caught, 0]
            d[caught, 2] = axis[1] - mid[caught, 2]
    d = d - (d * u).sum(1)[:, None] * u
    d /= np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
    t = np.zeros(len(on))
    out = np.zeros(len(on), dtype=bool)
    for _ in range(MEET_STEPS):
        go = ~out
        if not go.any():
            break
        t[go] += np.maximum(-sd[go], 0.003)
        sd[go] = job.body.signed_distance(mid[go] + d[go] * t[go, None], max_distance=0.5)
        out |= np.isfinite(sd) & (sd > 0.0)
    margin = job.tuning.cloth.tolerance + job.tuning.sew.meet_margin
    # a way out farther than the pair's gap crossed the body (a sleeve's underarm pair whose
    # midpoint lies in the torso's side, sent across the chest): such a pair meets at the surface
    # nearest its midpoint instead (the armpit). (A trouser leg's inseam pair round the leg goes
    # out about half its gap: the nearest surface could be the leg's outer side.)
    far = ~out | (t > np.linalg.norm(gap, axis=1))
    if far.any():
        _, cpt, normal, face, _ = job.body.closest(mid[far])
        ok = face >= 0
        k = on[far][ok]
        sewing.meet[k] = cpt[ok] + normal[ok] * margin
        sewing.meet_on[k] = True
    near = out & ~far
    if near.any():
        k = on[near]
        sewing.meet[k] = mid[near] + d[near] * (t[near] + margin)[:, None]
        sewing.meet_on[k] = True


def _lone_open(welded: np.ndarray, seam_id: np.ndarray) -> bool:
    """Whether every open pair is alone on its stitch (its neighbours along the stitch are sewn)."""
    open_ = ~welded
    same = seam_id[1:] == seam_id[:-1]
    return not (open_[1:] & open_[:-1] & same).any()


def _lone_outside(job: _Dressing, x: np.ndarray, pairs: np.ndarray, welded: np.ndarray) -> bool:
    """_lone_open, and every open pair's midpoint outside the body (job.body; None: no): a pair
    eased in across the body would be welded through it."""
    if job.body is None or not _lone_open(welded, job.garment.seam_id):
        return False
    p = pairs[~welded]
    return bool((job.body.signed_distance(0.5 * (x[p[:, 0]] + x[p[:, 1]]), max_distance=0.1) > 0.0).all())


def _stalled(out: _Pull, stall: deque, it: int, dt: float, t, lone: bool = False, snap: bool = True) -> bool:
    """Whether the seams stopped closing (the widest gap's median shrank < 1 mm from the older half
    of the stall window to the recent one; its median, not its least: a gap swinging 1.7-3 cm
    for seconds has a new least now and then without closing): welded where they are if within
    snap_gap (now and in the median, a swaying pair included), given up (out.gave_up) where the
    median is wider (a gap swinging about snap_gap, neither, had sewn on to the end of the budget:
    minutes of wall time under cloth-cloth contact). lone: every open pair is alone on its stitch
    (_lone_open): then within snap_lone_gap. snap: whether a stall within it may be welded yet
    (SewTuning.snap_after); a wider one gives up whenever it is judged."""
    h = len(stall) // 2
    older, recent = list(stall)[:h], list(stall)[h:]
    if np.median(older) - np.median(recent) >= 0.001:
        return False
    g = stall[-1]
    within = max(t.snap_gap, t.snap_lone_gap) if lone else t.snap_gap
    if g <= within and np.median(recent) <= within:
        if not snap:
            return False
        out.snapped = int((~out.welded).sum())
        out.gap_max = max(out.gap_max, g)
        out.welded[:] = True
        return True
    if np.median(recent) > within:
        out.gave_up = ((it + 1) * dt, min(recent), max(recent))
        return True
    return False


OPEN_WHY = "The garment may be too small for this body (try a larger size) or the panels start too far apart"


def _open_seams(job: _Dressing, model: ClothModel, state: ClothState, pull: _Pull, pulls: list) -> SimulationError:
    """The error of seams that stayed open: which, how wide, after how long."""
    t, garment, welded, gaps = job.tuning.sew, job.garment, pull.welded, pull.gaps
    open_ids = np.unique(garment.seam_id[~welded])
    worst = {int(s): float(gaps[(garment.seam_id == s) & ~welded].max()) for s in open_ids}
    names = ", ".join(f"{garment.stitch_names[s]} ({g * 100:.1f} cm)" for s, g in
                      sorted(worst.items(), key=lambda kv: -kv[1])[:5])
    gave_up = pull.gave_up
    when = (f"did not close within {t.budget:.1f} s of simulated time" if gave_up is None else
            f"stopped closing after {gave_up[0]:.1f} s of simulated time (the widest gap stayed "
            f"{100 * gave_up[1]:.1f}-{100 * gave_up[2]:.1f} cm for {t.snap_stall:.1f} s)")
    again = f" (sewn twice, pulled at {pulls[0]:g} and {pulls[-1]:g} m/s)" if len(pulls) > 1 else ""
    small = _too_small_panels(job, model, state, welded)
    # (the stall is the small part's where a seam of it is open at least half as wide as the widest:
    # else it stalls elsewhere -- a skirt seam 22 cm open beside a bodice 16 % stretched, 7 cm open
    # at it -- and no knit sews it; the words stay, the fabric ladder stops)
    cause = small is not None and _stalls_at(garment, welded, gaps, small[2])
    crotch, short = _crotch_short(job, state, welded)
    op = garment.seams[~welded]
    open_panels = sorted({garment.panel_names[p] for p in np.unique(garment.panel[op.ravel()])})
    pinched = pinched_open(garment, welded, gaps)
    round_ = _round_words(job, state.x, small[2]) if small and not crotch else None
    why = (crotch if crotch else f"{small[0]}: that part is too small for this body{round_ or ''} (try a larger "
           "size)" if small else _pinched_why(pinched) if pinched else OPEN_WHY)
    err = SimulationError(f"sewing {when}{again}; open seams: {names}. {why}")
    if cause and not crotch:  # (a fit, not the sewing: engine.scene.tryon drapes it in a stretchier knit)
        err.small_part, err.tight_panels = small[1], small[2]
    if crotch:  # (reach, the tops' height, the body's centre x and length, m: tryon lowers the garment)
        err.crotch = short
    err.positions, err.triangles = state.x.copy(), _triangles(model)  # for a picture
    err.open_points = 0.5 * (state.x[op[:, 0]] + state.x[op[:, 1]])  # (where they lie: tryon's hints)
    err.open_panels = open_panels
    err.too_small = True  # (engine.scene.garments.add_size_hint)
    # where the open seams were placed (engine.scene.garments.arms_in_the_way)
    err.open_top = float(garment.positions[op.ravel(), 1].max())
    return err


SMALL_STALL = 0.5  # a part too small stalls the sewing where a seam of it is open this share of the widest gap


def _stalls_at(garment: Garment, welded: np.ndarray, gaps: np.ndarray, names: list[str]) -> bool:
    """Whether the open pairs of the panels named (a part too small: _too_small_panels) are open
    at least SMALL_STALL as wide as the widest open pair: the stall is theirs."""
    open_ = ~welded
    if not open_.any():
        return False
    on = np.isin(garment.panel[garment.seams], [garment.panel_names.index(n) for n in names]).any(axis=1)
    at = open_ & on
    return bool(at.any() and gaps[at].max() >= SMALL_STALL * gaps[open_].max())


def _round_words(job: _Dressing, x: np.ndarray, names: list[str]) -> str | None:
    """"; at 'cuff_f', 'cuff_b' the cloth is 16.6 cm round (at rest) where the body is 29.3 cm
    round ..." (engine.scene.girth; x: (garment vertices, 3)), or None where the body is not known,
    no part is named or none wraps it."""
    if job.body is None or not names:
        return None
    rings = part_girths(job.garment, x, names, job.body.verts, job.body.faces)
    top = max(FABRICS.values(), key=lambda f: f.strain_threshold)
    words = girth_words(rings, (top.name, top.strain_threshold))
    return f"; {words}" if words else None


def pinched_outlines(names: list[str]) -> str:
    """"panel X's outline crosses itself" / "the outlines of panels X, Y cross themselves"."""
    if len(names) == 1:
        return f"panel {names[0]}'s outline crosses itself"
    return f"the outlines of panels {', '.join(names)} cross themselves"


def pinched_open(garment: Garment, welded: np.ndarray, gaps: np.ndarray) -> list[str]:
    """The panels whose outlines cross themselves (Garment.pinched) beside the widest open pairs
    (at least half the widest gap): a crossed outline elsewhere is not why a skirt stalled."""
    if welded.all() or not garment.pinched:
        return []
    wide = garment.seams[~welded & (gaps >= 0.5 * float(gaps[~welded].max()))]
    return sorted({garment.panel_names[p] for p in np.unique(garment.panel[wide.ravel()])} & set(garment.pinched))


def _pinched_why(names: list[str]) -> str:
    """Why seams beside panels whose outlines cross themselves stay open: GarmentCode draws a
    neckline cut past the armholes so, and the parts beyond the crossing (a strap, a side) are
    joined to the rest at one point, so nothing holds them where their seams are to meet."""
    return (f"Beside them {pinched_outlines(names)} (meshed joined where the edges cross): the parts "
            "beyond a crossing hang from a point and cannot be held where their seams meet (a "
            "neckline cut past the armhole) -- check those edges in the pattern")


def _too_small_panels(job: _Dressing, model: ClothModel, state: ClothState,
                      welded: np.ndarray) -> tuple[str, float, list[str]] | None:
    """The panels of the open seams whose cloth is stretched past the fabric's threshold +
    DrapeTuning.too_tight over a tenth of it (90th percentile of its springs) while the seams
    stall: a cuff or band smaller round than the limb it is to close round, named, the
    largest of those strains, and all their names; else None."""
    g = job.garment
    limit = get_fabric(job.request.fabric).strain_threshold + job.tuning.drape.too_tight
    s, strain = spring_strains(model, state.x)
    found = []
    for p in np.unique(g.panel[g.seams[~welded].ravel()]):
        on = (g.panel[s[:, 0]] == p) & (g.panel[s[:, 1]] == p)
        if on.sum() >= 10:
            p90 = float(np.percentile(strain[on], 90))
            if p90 > limit:
                found.append((p90, g.panel_names[p]))
    if not found:
        return None
    found.sort(reverse=True)
    names = ", ".join(f"'{n}' {100 * v:.0f} %" for v, n in found[:4])
    return (f"Beside them the cloth is stretched far past what {job.request.fabric} allows "
            f"({100 * (limit - job.tuning.drape.too_tight):.0f} %) over a tenth of a panel or more: {names}",
            found[0][0], [n for _, n in found])


CROTCH_NEAR = 0.06  # m: open pairs this near the body's centre plane ...
CROTCH_BELOW = 0.08  # m: ... and this near the height of its crotch meet under it (_crotch_short)
CROTCH_ACROSS = 2.0  # ... from front to back: across the middle, or this many times as far along z as x
CROTCH_SHORT = 0.95  # the cloth's way through the crotch shorter than this share of the body's
# a pair whose cloth reaches less than this up both its panels to their tops is no crotch seam hanging
# from a waist (a skirt level's side seam caught at crotch height): no rise to lengthen, none lowered
CROTCH_MIN_REACH = 0.05  # m


def sagittal_length(verts: np.ndarray, faces: np.ndarray, x0: float, top: float) -> tuple[float, float]:
    """The body's outline in the plane x = x0 below the height `top` -- down the front, under the
    crotch, up the back: (its length m, its lowest height m); (0, nan) where the plane misses it."""
    d = verts[faces, 0] - x0  # (F, 3)
    cut = (d.min(1) < 0) & (d.max(1) > 0)
    ends = []
    for i in range(3):  # where each cut triangle's edges cross the plane (two of its three)
        a, b = d[cut, i], d[cut, (i + 1) % 3]
        pa, pb = verts[faces[cut, i]], verts[faces[cut, (i + 1) % 3]]
        cross = (a > 0) != (b > 0)
        t = (a / np.where(cross, a - b, 1.0))[:, None]
        ends.append(np.where(cross[:, None], pa + t * (pb - pa), np.nan))
    e = np.stack(ends, 1)  # (C, 3, 3)
    ok = ~np.isnan(e[:, :, 0])
    two = ok.sum(1) == 2
    e, ok = e[two], ok[two]
    first = np.argmax(ok, 1)
    second = 2 - np.argmax(ok[:, ::-1], 1)
    p, q = e[np.arange(len(e)), first], e[np.arange(len(e)), second]
    p, q = np.where((p[:, 1] <= q[:, 1])[:, None], p, q), np.where((p[:, 1] <= q[:, 1])[:, None], q, p)  # p lower
    below = p[:, 1] < top
    if not below.any():
        return 0.0, float("nan")
    p, q = p[below], q[below]
    over = q[:, 1] > top  # (a segment crossing the height: its part below)
    s = np.where(over, (top - p[:, 1]) / np.where(over, q[:, 1] - p[:, 1], 1.0), 1.0)[:, None]
    return float(np.linalg.norm(s * (q - p), axis=1).sum()), float(p[:, 1].min())


def _crotch_length(verts: np.ndarray, faces: np.ndarray, xc: float, top: float) -> tuple[float, float]:
    """The shortest of sagittal_length's within 1 cm either side of x = xc (where the legs part:
    a plane just inside a thigh runs down it) and its lowest height."""
    return min((sagittal_length(verts, faces, xc + dx, top) for dx in np.linspace(-0.01, 0.01, 9)),
               key=lambda r: r[0] if r[0] > 0 else np.inf)


def crotch_fit_drop(verts: np.ndarray, faces: np.ndarray, reach: float, y_top: float, xc: float,
                    most: float) -> float | None:
    """How far (m) a lower garment whose cloth reaches `reach` through the crotch from tops at
    y_top must hang lower for the body's outline through its crotch from there to be no longer
    than that (_crotch_length; bisection); None where even `most` lower is not enough."""
    if _crotch_length(verts, faces, xc, y_top - most)[0] > reach:
        return None
    lo, hi = 0.0, most
    for _ in range(20):
        m = 0.5 * (lo + hi)
        lo, hi = (m, hi) if _crotch_length(verts, faces, xc, y_top - m)[0] > reach else (lo, m)
    return hi


def _crotch_short(job: _Dressing, state: ClothState, welded: np.ndarray) -> tuple[str | None, tuple | None]:
    """Where open pairs meet under the body's crotch (within CROTCH_NEAR of its centre plane and
    CROTCH_BELOW of its lowest point there, one end in front and one behind), whether the cloth
    can reach round it: the flat distance from each side's point up its panel to that panel's top
    (where it is held), front and back together, against the body's outline through the crotch
    from the height the tops hang at -- where those pairs are open at least SMALL_STALL as wide as
    the widest (else the stall is not the rise's). A rise shorter than CROTCH_SHORT of it is named, with both
    lengths, and (reach m, the tops' height m, the body's centre x, the body's length m); else
    (None, None)."""
    if job.body is None:
        return None, None
    g, x = job.garment, state.x
    verts, faces = job.body.verts, job.body.faces
    xc = float(np.median(verts[:, 0]))
    pairs = g.seams[~welded]
    mid = 0.5 * (x[pairs[:, 0]] + x[pairs[:, 1]])
    near = np.abs(mid[:, 0] - xc) < CROTCH_NEAR
    if not near.any():
        return None, None
    _, low = _crotch_length(verts, faces, xc, float(mid[near, 1].max()) + CROTCH_BELOW)
    if not np.isfinite(low):
        return None, None
    # (a pair from the front to the back, under it: not a skirt's centre seam, open in front. Front
    # and back of the body's middle there, or open front to back more than sideways: trousers pulled
    # up into the crotch leave their crotch seams open across it, both ends a little in front of
    # the middle of a body whose buttocks reach further back than its front -- f_smpl 109_006)
    by = (np.abs(verts[:, 1] - low) < 0.05) & (np.abs(verts[:, 0] - xc) < 0.1)
    zc = float(np.median(verts[by, 2])) if by.any() else float(np.median(verts[:, 2]))
    d = x[pairs[:, 0]] - x[pairs[:, 1]]
    across = ((x[pairs[:, 0], 2] - zc) * (x[pairs[:, 1], 2] - zc) < 0) | (np.abs(d[:, 2]) > CROTCH_ACROSS * np.abs(d[:, 0]))
    near &= (np.abs(mid[:, 1] - low) < CROTCH_BELOW) & across
    if not near.any():
        return None, None
    worst = None
    gap = np.linalg.norm(x[pairs[near, 0]] - x[pairs[near, 1]], axis=1)
    if gap.max() < SMALL_STALL * np.linalg.norm(d, axis=1).max():
        return None, None  # (the stall is elsewhere: shorts' cuffs 12 cm open round the thighs, the crotch 3 cm)
    for a, b in pairs[near][np.argsort(-gap)[:4]]:  # (the widest four: each pair costs 9 sections of the body)
        reach, tops = 0.0, []
        for v in (a, b):
            on = np.flatnonzero(g.panel == g.panel[v])
            top = on[x[on, 1] >= x[on, 1].max() - 0.02]  # (the panel's top edge, as it hangs)
            reach += float(np.linalg.norm(g.uv[top] - g.uv[v], axis=1).min())
            tops.append(float(x[top, 1].mean()))
        y_top = min(tops)
        body_len, _ = _crotch_length(verts, faces, xc, y_top)
        if body_len > 0 and CROTCH_MIN_REACH <= reach < CROTCH_SHORT * body_len and \
                (worst is None or reach / body_len < worst[0]):
            worst = (reach / body_len, reach, body_len, y_top)
    if worst is None:
        return None, None
    _, reach, body_len, y_top = worst
    return (f"The open seams meet under the body's crotch, and the cloth cannot reach round it: from the "
            f"top of the panels either side (at {y_top:.2f} m) down the front to the crotch and up the back is at most "
            f"{100 * reach:.0f} cm of cloth, where the body measures {100 * body_len:.0f} cm through its "
            "crotch from that height -- the rise is too short for this body (lengthen the crotch seams, or "
            "let the top sit lower)"), (reach, y_top, xc, body_len)


def drape(model: ClothModel, state: ClothState, collider: Collider | None, request: TryOnOptions = TryOnOptions(),
          tuning: Tuning = Tuning(), progress: Progress = _noop, observer: Observer | None = None,
          gravity_from: float = 1.0, solver: ClothSolver | None = None,
          attachment: Attachment | None = None, release: tuple | None = None,
          around: Around = Around()) -> DrapeResult:
    """The drape stage alone (module doc), from `state` (changed in place) of the sewn `model`:
    until the shape stops moving, or the budget ends; a garment left stretched past the fabric's
    threshold + too_tight is refused. Gravity grows from `gravity_from` x g over the rest of the
    ramp. `solver` (of this model and collider) carries its iteration count and timing on.
    attachment: vertices kept in front of planes (engine.scene.attach). The result's seam fields are zero (no seams are open in a sewn model).
    release: (PassThrough, the model's vertices it lets through) while `solver` answers them from the
    body less some parts: when the drape settles, `collider` (the whole body) takes over; where
    the left-out parts touch the cloth then, the drape goes on until it settles again.
    around: the ground and the body (Around)."""
    t = tuning.drape
    floor, body = around.floor, around.body
    tuning.validate()
    fabric = get_fabric(request.fabric)
    if solver is None:
        solver = ClothSolver(model, collider, dressing_config(request, tuning), dt=request.dt,
                             force_dt=request.force_dt)
    dt = solver.dt
    every = _drape_every(tuning, dt)
    fire = FireRelaxer() if t.relax == "fire" else None
    control = Control(damping_scale=t.fire_damping if fire is not None else t.damping, collide_every=every,
                      attachment=attachment, floor=floor)
    ramp = tuning.sew.gravity_ramp if fire is None else min(tuning.sew.gravity_ramp, t.fire_ramp)
    t0 = time.perf_counter()
    it0 = solver.iterations
    timing0 = dict(solver.timing)
    budget = int(np.ceil(t.budget / dt))
    min_it = int(np.ceil(t.min_time / dt))
    sub = max(1, int(np.ceil(t.settle_time / dt / SETTLE_CHECKS)))  # steps between settle tests
    window = sub * SETTLE_CHECKS
    check_every = max(1, int(GAP_CHECK / dt))
    observe = max(1, int(tuning.observe_every / dt))
    tri1 = _triangles(model) if observer is not None else None
    settled = False
    snaps = deque([state.x.copy()], maxlen=2 * SETTLE_CHECKS + 1)  # positions every `sub` steps
    guards = deque(maxlen=SETTLE_CHECKS)  # steps of each sub-window in which the strain guard acted
    # max strain at the last checks
    strains = deque(maxlen=max(1, int(round(max(t.refuse_after, t.knit_tight_after) / (sub * dt)))))
    refuse = fabric.strain_threshold + t.too_tight
    tight = fabric.strain_threshold + t.tight_every_step
    give_up = fabric.strain_threshold + t.knit_give_up
    n_give_up = max(1, int(round(t.knit_give_up_after / (sub * dt))))
    n_tight = max(1, int(round(t.knit_tight_after / (sub * dt))))
    n_refuse = max(1, int(round(t.refuse_after / (sub * dt))))
    n_polish = 0 if t.polish_tight_after is None else max(1, int(round(t.polish_tight_after / (sub * dt))))
    every_step_from = None
    drift, guard_steps, guard_share = np.inf, 0, 0.0
    released = None if release is None else False  # (whether the whole body took over at a settle)
    polished, config0 = False, solver.config  # (polish_at: the doubled passes end with this drape)
    tris = _triangles(model) if body is not None and t.stand_out is not None and fire is not None else None
    stood = None  # (steps, share): when FIRE settled with cloth standing out, and how much
    for it in range(budget):
        # gravity goes on growing from where sewing left it (no second ramp from zero)
        control.gravity_scale = min(1.0, gravity_from + (it + 1) * dt / ramp)
        solver.step(state, control)
        if fire is not None:
            fire.after_step(solver, state)
        guard_steps += solver.guarded > 0
        if observer is not None and it % observe == 0:
            observer("draping", state.x, tri1, None)
        if it % check_every == 0:
            _check_finite(state, "draping", floor)
            progress("draping", _settle_fraction(drift, t.settle_speed),
                     f"drift {drift * 100:.2f} cm/s (at rest below {t.settle_speed * 100:.1f})")
        if (it + 1) % sub:
            continue
        snaps.append(state.x.copy())
        guards.append(guard_steps)
        guard_steps = 0
        if stood is not None and len(stood) == 2 and (it + 1) % window == 0:
            if ((it + 1 - stood[0]) * dt >= t.stand_out_for or
                    standing_out(state.x, tris, body, floor, t, t.stand_out_hung) < 0.5 * t.stand_out):
                fire.free = None  # (it came down, or had its time: all at rest with FIRE from here)
                control.damping_scale = t.fire_damping
                stood = (*stood, it + 1)
                snaps.clear()
                snaps.append(state.x.copy())
                continue
        strains.append(solver.max_strain(state))
        if (control.collide_every > 1 and strains[-1] > tight and (it + 1) * dt > t.tight_grace
                and tuning.collide_every is None):
            # stretched past what the strain guard holds: the strain limit and the body are
            # fighting (a garment too small, cloth wedged between arm and torso) -- they
            # alternate at every step from here on
            control.collide_every = 1
            every_step_from = it + 1
        if (n_polish and t.polish_at is not None and not polished and len(strains) >= n_polish
                and min(list(strains)[-n_polish:]) > fabric.strain_threshold + t.polish_at):
            # (stretched past polish_at that long while still moving: polished now -- the strain
            # guard and the contacts had fought for seconds before it settled, or to the budget)
            polished = True
            every_step_from = _polish(solver, control, tuning, it, every_step_from)
        if it >= min_it and len(strains) >= n_refuse and (least := min(list(strains)[-n_refuse:])) > refuse:
            raise _too_small(state, model, least, fabric,
                             f"for {n_refuse * sub * dt:.1f} s of draping it stayed stretched at least")
        if t.give_up and it >= min_it and len(strains) >= n_give_up and \
                (least := min(list(strains)[-n_give_up:])) > give_up:
            err = _too_small(state, model, least, fabric,
                             f"for {n_give_up * sub * dt:.2f} s of draping it stayed stretched at least")
            err.gave_up = True  # (DrapeTuning.give_up: another fabric follows)
            raise err
        if t.give_up and it >= min_it and len(strains) >= n_tight and \
                (least := min(list(strains)[-n_tight:])) > tight:
            err = _too_small(state, model, least, fabric,
                             f"for {n_tight * sub * dt:.2f} s of draping it stayed stretched at least")
            err.gave_up = True
            raise err
        if len(snaps) == snaps.maxlen:
            # settled = the shape stopped moving: RMS displacement over each of the last two
            # windows, as a speed (contacts keep a jitter of a few mm/s that goes nowhere)
            older = _rms_move(snaps[SETTLE_CHECKS], snaps[0]) / (window * dt)
            drift = _rms_move(snaps[-1], snaps[SETTLE_CHECKS]) / (window * dt)
            guard_share = sum(guards) / window
            full = gravity_from + (it + 1 - window) * dt / ramp >= 1.0  # the last window at full g
            if max(older, drift) < t.settle_speed and it >= min_it and full:
                if release is not None:
                    caught = release[0].caught(collider, state.x, release[1])
                    solver.set_collider(collider)
                    release, released = None, True
                    if caught:  # (the parts left out meet the cloth: it settles again against them)
                        snaps.clear()
                        snaps.append(state.x.copy())
                        continue
                if (t.polish_at is not None and not polished and strains[-1] > fabric.strain_threshold + t.polish_at):
                    # (settled with the guard not holding: the strain limit and the contacts
                    # alternate twice as often, checked every step, until it settles again)
                    polished = True
                    every_step_from = _polish(solver, control, tuning, it, every_step_from)
                    snaps.clear()
                    snaps.append(state.x.copy())
                    continue
                if tris is not None and stood is None and (share := standing_out(state.x, tris, body, floor, t)) > t.stand_out:
                    # FIRE zeroes every velocity whenever the cloth's power turns negative, and a
                    # circle skirt standing out flat from the waist -- a balance, unstable, that
                    # folds only once a fall has built up somewhere -- comes to rest so. The cloth
                    # away from the body is let fall with viscous damping alone, and falls into
                    # folds; FIRE holds the rest (a strapless bodice slid down to the waist when
                    # all of it fell so; docs/tuning.md, stand_out)
                    stood = (it + 1, share)
                    fire.free = body.signed_distance(state.x, max_distance=t.stand_out_far) > 0.5 * t.stand_out_far
                    control.damping_scale = t.damping
                    snaps.clear()
                    snaps.append(state.x.copy())
                    continue
                settled = True
                break
    if release is not None:  # (it never settled: what it ends as meets the whole body from here on)
        solver.set_collider(collider)
    solver.config = config0
    strain = solver.max_strain(state)
    if strain > refuse:
        raise _too_small(state, model, strain, fabric, "after draping it is stretched")
    return DrapeResult(positions=state.x.copy(), triangles=_triangles(model), model=model, state=state,
                       iterations={"draping": solver.iterations - it0},
                       timing={"draping": time.perf_counter() - t0,
                               **{f"{k}_total": solver.timing[k] - timing0.get(k, 0.0) for k in solver.timing}},
                       seam_gap_max=0.0, settled=settled, kinetic_energy=solver.kinetic_energy(state),
                       strain_max=strain, dt=dt, strain_guard=solver.config.strain_guard,
                       guard_share=guard_share, snapped=0, released=released,
                       stood_out=None if stood is None else {
                           "share": stood[1], "at_s": stood[0] * dt,
                           "viscous_s": ((stood[2] if len(stood) > 2 else it + 1) - stood[0]) * dt},
                       collide_every={"draping": int(every), **({"every_step_from_s": every_step_from * dt}
                                                                if every_step_from is not None else {})})


def standing_out(x: np.ndarray, tris: np.ndarray, body, floor: float | None, tuning, level: float | None = None) -> float:
    """The share of the cloth's area that stands out from the body unheld: farther than
    stand_out_far from it, tilted within 45 degrees of level (|normal y| > `level`, default
    stand_out_level), and not on the ground. Cloth at rest hangs from where it is held; a part
    lying level in the air is held up by its own stiffness (a circle skirt's flat fan round the hips)."""
    t = tuning.drape if hasattr(tuning, "drape") else tuning
    tilt = t.stand_out_level if level is None else level
    p = x[tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = np.linalg.norm(n, axis=1)
    if area.sum() <= 0.0:
        return 0.0
    c = p.mean(1)
    flat = np.abs(n[:, 1]) > tilt * np.maximum(area, 1e-30)
    if floor is not None:
        flat &= c[:, 1] > floor + t.stand_out_far
    if not flat.any():
        return 0.0
    far = np.zeros(len(c), dtype=bool)
    far[flat] = body.signed_distance(c[flat], max_distance=2 * t.stand_out_far) > t.stand_out_far
    return float(area[far].sum() / area.sum())


def _polish(solver: ClothSolver, control: Control, tuning: Tuning, it: int,
            every_step_from: int | None) -> int | None:
    """Polish a drape (DrapeTuning.polish_at): collisions checked every step (unless the tuning
    fixes how often), the strain and contact passes doubled on `solver` until drape() ends;
    returns the step collisions went every step from."""
    if control.collide_every > 1 and tuning.collide_every is None:
        control.collide_every = 1
        every_step_from = it + 1
    solver.config = replace(solver.config, vm_passes=2 * solver.config.vm_passes,
                            contact_rounds=2 * solver.config.contact_rounds)
    return every_step_from


FINISH_REACH = 0.05  # m: the mesh is searched this far round each point (cloth this deep is not finished)
FINISH_STRAIN = 0.002  # the finish is kept only where it ends at most this much more stretched
# ... or at most this past the fabric's threshold (under the report's tight mark, 1 %): f_smpl 67_007
# in jersey ended 2.3 mm deep at 15.4 %, the finish 0 mm at 15.8 %, and the deep drape stood
FINISH_WITHIN = 0.008


def _finish_exact(job: _Dressing, res: DrapeResult, solver: ClothSolver, attachment, floor) -> DrapeResult:
    """A drape that ends with cloth deeper in the body than DrapeTuning.finish_pen, measured
    against its mesh, goes on briefly against the mesh itself (ObjectSpaceCollider) instead of the
    maps, until it settles again: the maps' 5 mm texels round off the edges of the feet and the
    tight curves a stretched knit lies on, and cloth resting on the maps' surface there lies 2-3 mm
    inside the mesh. Kept where it settles less deep and no more stretched; res.finish says so."""
    from engine.collide.bvh import RowsObjectSpaceCollider, penetration_depth

    t = job.tuning
    before = float(penetration_depth(job.body, res.positions)[0].max())
    if before <= t.drape.finish_pen:
        return res
    job.progress("draping", 1.0, f"cloth {1000 * before:.1f} mm inside the body: settling it against the body's "
                                 "mesh itself")
    # (asked for the points whose answers may have changed alone: the cloth has settled)
    exact = RowsObjectSpaceCollider(job.body.verts, job.body.faces, tolerance=t.cloth.tolerance,
                                    max_distance=FINISH_REACH)
    tuning = replace(t, drape=replace(t.drape, min_time=t.drape.settle_time, budget=t.drape.finish_budget,
                                      polish_at=None, give_up=False))
    maps = solver.collider
    solver.set_collider(exact)
    try:
        fin = drape(res.model, ClothState(res.state.x.copy(), res.state.v.copy()), exact, job.request, tuning,
                    job.progress, job.observer, gravity_from=1.0, solver=solver, attachment=attachment,
                    around=Around(floor))
    except SimulationError as e:
        fin, why = None, str(e)
    finally:
        solver.set_collider(maps)
    after = float(penetration_depth(job.body, fin.positions)[0].max()) if fin is not None else np.inf
    limit = max(res.strain_max + FINISH_STRAIN, get_fabric(job.request.fabric).strain_threshold + FINISH_WITHIN)
    kept = fin is not None and fin.settled and after < before and fin.strain_max <= limit
    res.finish = {**({"failed": why} if fin is None else {}), "penetration_mm_before": 1000 * before,
                  "penetration_mm_after": 1000 * after if fin else None,
                  "iterations": fin.iterations["draping"] if fin else None, "kept": bool(kept),
                  "settled": bool(fin.settled) if fin else None, "strain": fin.strain_max if fin else None}
    if not kept:
        return res
    res.finish["strain_before"] = res.strain_max
    for k, v in fin.timing.items():
        res.timing[k] = res.timing.get(k, 0.0) + v
    res.iterations["draping"] += fin.iterations["draping"]
    res.positions, res.state, res.kinetic_energy = fin.positions, fin.state, fin.kinetic_energy
    res.strain_max, res.guard_share = fin.strain_max, fin.guard_share
    return res


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
    s, strain = spring_strains(model, x)
    k = int(np.argmax(strain))
    return float(strain[k]), 0.5 * (x[s[k, 0]] + x[s[k, 1]])


def _too_small(state: ClothState, model: ClothModel, strain: float, fabric, how: str) -> SimulationError:
    err = SimulationError(f"the garment is too small for this body: {how} {100 * strain:.0f} % where "
                          f"{fabric.name} allows {100 * fabric.strain_threshold:.0f} %; try a larger size")
    err.positions, err.triangles = state.x.copy(), _triangles(model)  # for a picture
    err.too_small = True  # (engine.scene.garments)
    err.stretched_at = most_stretched(state.x, model)[1]  # (engine.scene.garments.arms_in_the_way)
    err.strain = strain
    return err


def _triangles(m: ClothModel) -> np.ndarray:
    q = m.quads
    return np.concatenate([m.tris, q[:, [0, 1, 2]], q[:, [0, 2, 3]]]).astype(np.int32)


def _rms_move(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


# (at the default step, which is the stability bound, the usual cause is cloth sewn shut tangled
# round the body: GarmentCode's mean_female 11_019, a hooded top, over one shoulder)
UNSTABLE_WHY = ("the garment may have been sewn shut tangled round the body (look at the sewing in the live "
                "view); a smaller time step (--dt) may hold it")


def _check_finite(state: ClothState, stage: str, floor: float | None = None) -> None:
    if not (np.all(np.isfinite(state.x)) and np.all(np.isfinite(state.v))):
        raise SimulationError(f"the cloth became unstable while {stage} (non-finite positions): {UNSTABLE_WHY}, "
                              "or a softer fabric")
    if state.x[:, 1].max() < (FELL_BELOW if floor is None else floor + FELL_ON_FLOOR):
        raise SimulationError(f"the garment fell off the body while {stage} (all of it below the feet): it is far "
                              "too large for this body, or its pattern places it away from the body; try a "
                              "smaller size, or check the panels' translation")
    if np.abs(state.x).max() > 100.0:
        raise SimulationError(f"the cloth flew off while {stage} (a vertex is more than 100 m away): {UNSTABLE_WHY}")
