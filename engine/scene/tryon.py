"""Plan and run a static try-on: body + garment -> sewn, draped garment, pictures, report.

The planner looks at the scene first and records what it leaves out ("left out: ... because
..."): e.g. arm maps for a garment that stays below the shoulders, map rows above the garment.
"""

from __future__ import annotations

import json
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from engine.body.types import SEGMENTS, Body
from engine.cloth.fabrics import get_fabric
from engine.errors import InputError, SimulationError, TryonError
from engine.garment.garment import Garment, build_garment
from engine.pattern.spec import PatternSpec
from engine.scene.drape import DrapeResult, Progress, ground, most_stretched, pinched_outlines, sew_and_drape
from engine.scene.garments import PATTERN_SIZE_ADVICE, dress_in_size
from engine.scene.attach import attachment, stands_off
from engine.scene.request import TryOnOptions, TryOnRequest
from engine.scene.tuning import Tuning


@dataclass
class TryOnPlan:
    texel: float
    window: tuple[float, float] | None
    segments: list[str] | None
    left_out: list[str] = field(default_factory=list)


def plan_maps(body: Body, garment: Garment, texel: float, collision: str) -> TryOnPlan:
    """Decide which maps to render for this body and garment (DESIGN: a scene leaves out what
    it does not need). The same maps serve sewing and draping: a top without sleeves sewn
    without the arm maps (its shoulder seams then close through the arm's root) left cloth inside
    the arm, whose front and back maps pushed neighbouring vertices out on opposite sides when
    the drape brought the arms back."""
    left: list[str] = ["velocity maps, because the body does not move"]
    top = float(garment.positions[:, 1].max())
    window = (0.0, min(body.vertices[:, 1].max(), top + 0.15))
    if window[1] < body.vertices[:, 1].max() - 1e-6:
        left.append(f"map rows above {window[1]:.2f} m, because the garment starts at {top:.2f} m "
                    "(cloth falls, it does not climb)")
    if collision == "object":
        left = ["collision maps, because object-space collision (BVH) was chosen"]
        return TryOnPlan(texel, None, None, left)
    if body.segments is None:
        return TryOnPlan(texel, window, None, left)
    present = set(int(s) for s in np.unique(body.segments))
    segs = [s for s in ("torso", "left_arm", "right_arm", "left_leg", "right_leg")
            if SEGMENTS.index(s) in present]
    # a garment whose top stays below the armpits never meets the arms
    arm = np.isin(body.segments, [SEGMENTS.index("left_arm"), SEGMENTS.index("right_arm")])
    torso = body.segments == SEGMENTS.index("torso")
    armpit = float(body.vertices[arm, 1].min()) if arm.any() else np.inf
    if top < armpit - 0.05 and torso.any():
        segs = [s for s in segs if "arm" not in s]
        left.append(f"arm maps, because the garment stays below the arms (top {top:.2f} m, "
                    f"armpits {armpit:.2f} m)")
    head = body.segments == SEGMENTS.index("head")
    if head.any() and top + 0.05 > float(body.vertices[head, 1].min()):
        segs = ["head"] + segs  # the head segment holds the neck, where necklines sit
    else:
        left.append("head maps, because the garment stays below the neck")
    return TryOnPlan(texel, window, segs, left)


def _armpit_y(body: Body) -> float:
    """The armpits' world height (engine.body.measure), or NaN where the body cannot be measured."""
    return _world_height(body, "armpit_height")


def _world_height(body: Body, name: str) -> float:
    """A measured height (engine.body.measure's `name`) in world y, or NaN where the body cannot
    be measured."""
    from engine.body.measure import measure

    try:
        return float(body.vertices[:, 1].min()) + float(getattr(measure(body), name))
    except TryonError:
        return float("nan")


def fell_off(placed: np.ndarray, draped: np.ndarray, shoulder_y: float, same: bool = False) -> float | None:
    """How far (m) below the shoulders the top of a garment placed over them ended, where that is
    more than FELL; else None. (A hood or a collar that folds back still rests on the shoulders;
    straps that did not hold let the whole top down: GarmentCode's necklines cut past the
    armholes.) same: draped[i] is placed[i]'s vertex -- then each side placed over its shoulder
    is judged by its own cloth: one strap that held kept the top up while the other side fell to
    the waist (mean_female 37_025 in jersey)."""
    near = np.hypot(placed[:, 0], placed[:, 2]) < OVER_AXIS
    if not np.isfinite(shoulder_y) or not near.any() or placed[near, 1].max() < shoulder_y - OVER_SHOULDERS:
        return None
    below = shoulder_y - float(draped[:, 1].max())
    if same:
        for side in (-1.0, 1.0):
            on = near & (side * placed[:, 0] > SIDE_OF_AXIS)
            if on.any() and placed[on, 1].max() >= shoulder_y - OVER_SHOULDERS:
                below = max(below, shoulder_y - float(draped[on, 1].max()))
    return below if below > FELL else None


def _over_the_shoulders(garment, body: Body, inside, note: str | None) -> str | None:
    """Raise a pattern file's placed garment until its seams above the armpits can close over
    the body (engine.garment.place.seam_lift); returns the placement note, saying so."""
    from engine.garment.place import seam_lift

    armpit = _armpit_y(body)
    if not np.isfinite(armpit):
        return note
    dy = seam_lift(garment.positions, garment.seams, inside, armpit)
    if dy <= 0.0:
        return note
    garment.positions[:, 1] += dy
    said = (f"raised {100 * dy:.1f} cm so that the seams over the shoulders close over them (as placed they "
            "ran through the body)")
    return f"{note}; {said}" if note else f"the pattern's own placement, {said}"


def run_tryon(body: Body, spec: PatternSpec, request: TryOnOptions = TryOnOptions(), tuning: Tuning = Tuning(), *,
              place=None, source: str = "pattern", progress: Progress | None = None, observer=None,
              lift=None) -> tuple[DrapeResult, dict]:
    """Sew and drape `spec` on `body`; returns the result and the report (see DESIGN).
    place: the catalogue's placement function (None: the pattern's own, carried by landmarks).
    observer: see engine.scene.drape.Observer (the cloth as it is simulated, for a live view).
    lift: an engine.scene.arms.ArmLift of `body` -- sew and drape on its raised body (`place`
    made for that body), then lower the arms and settle on `body`.
    A pattern file that names no fabric (nor was one asked for) is draped in DEFAULT_FABRIC; if
    that leaves it stretched past the fabric's limit (tight, refused as too small while draping,
    or its seams stalled beside a part stretched far past it), it has no ease there -- a garment
    cut that close is sewn from a knit -- and it is draped again in each of CLOSE_FIT_FABRICS in
    turn, stretchier and stretchier, until one fits; the report's fabric_why and a warning say
    so. Every drape but the last stops as soon as it stays clearly tight (DrapeTuning.give_up);
    where the first gave up short of its own refusal mark, it is run to its end before the
    stretchiest knit. Before the knits: where the first drape named the parts it held at the
    fabric's limit over a tenth of them or more (engine.scene.drape.held_panels: cuffs, bands,
    a hood cut smaller round than the arm, waist or head), together at most PART_SHARE of the
    garment's cloth (more: the garment as a whole is cut for a knit), it is
    draped again with those parts in PART_KNIT -- as a maker sews a cuff or band from a rib
    knit -- and, where that names parts again, once more with those added; where the last names
    no new parts but held those in PART_KNIT again, or its seams stalled open at them, once more
    with those in RIB_KNIT (a rib stretches twice as far round; GarmentCode cuts some cuffs to the
    wrist's girth on sleeves that end on the forearm), the others kept in PART_KNIT, and where
    that names parts it had not, once more with those in PART_KNIT. The knits' drapes keep the
    parts found in a stretchier knit than theirs (a knit top whose cuffs need a rib). If none
    fits, the first fabric's drape or the stretchiest knit's (tight, noted) or the first's refusal
    stands. Where the first drape was placed lower for a short rise (_run_tryon's drop), every
    later one is placed as low."""
    request, fabric_why = with_fabric(request, spec)
    kw = dict(place=place, source=source, progress=progress, observer=observer, lift=lift)
    if place is not None or fabric_why != "the default" or request.fabric in CLOSE_FIT_FABRICS:
        return _run_tryon(body, spec, request, tuning, fabric_why, **kw)
    fab = get_fabric(request.fabric)
    say = progress or (lambda *a: None)
    quick = replace(tuning, drape=replace(tuning.drape, give_up=True))

    lowered = [None]  # (m lower, ...) where the first drape was placed lower for a short rise

    def attempt(req: TryOnOptions, t: Tuning, why: str, parts: dict | None = None):
        """A drape's (result, report), or the SimulationError that ended it; placed as low as the
        first drape ended (a rise found short is not sewn short again in each fabric)."""
        try:
            return _run_tryon(body, spec, req, t, why, panel_fabrics=parts, drop=lowered[0], **kw)
        except SimulationError as e:
            return e

    # the first drape stops early once it clearly ends tight (DrapeTuning.give_up): the knits follow
    first = attempt(request, quick, fabric_why)
    lowered[0] = getattr(first, "lowered", None) if isinstance(first, Exception) else first[0].lowered
    if isinstance(first, Exception) and not _no_fit(first):  # (sewing that stalled for another reason)
        raise first
    if _fits(first):
        return first
    said = [_how_it_fit(fab, first)]
    # the parts held at the limit in a knit (a rib cuff or band), the rest in the first fabric
    parts: dict[str, str] = {}
    out = first
    areas = _panel_areas(spec)
    ribbed = False
    for k in range(PART_ROUNDS + 2):
        held = _tight_parts(out)
        named = [n for n in held if n not in parts]
        if k == PART_ROUNDS:  # (the parts held in PART_KNIT too, or stalled open, and no others: in a rib)
            rib = set(held) | (set(getattr(out, "open_panels", ())) & set(parts))
            if not parts or named or not rib:
                break
            knit, trial, ribbed = RIB_KNIT, {n: RIB_KNIT if n in rib else f for n, f in parts.items()}, True
        elif k > PART_ROUNDS and not (ribbed and named):
            break
        elif not named:
            continue  # (the parts held again, or no parts: the rib, or the knits below)
        else:  # (or, sewn on in a rib, the parts it held next: a cuff's flared skirt below its band)
            knit, trial = PART_KNIT, {**parts, **{n: PART_KNIT for n in named}}
        if sum(areas.get(n, 0.0) for n in trial) > PART_SHARE * sum(areas.values()):
            break  # (most of the garment held: it is a garment for a knit, below)
        parts = trial
        say("sewing", 0.0, f"{said[0]}: draping it again with {_in_fabrics(parts)}")
        out = attempt(request, quick, fabric_why, parts)
        if _fits(out):
            out[1]["warnings"].append(f"{_in_fabrics(parts, 'sewn from')}, as a maker sews a part cut smaller "
                                      f"round than the body (a rib cuff or band): {said[0]}")
            return out
    tried = []  # (fabric, result or error) of each knit
    # the first fabric's drape to its end where it gave up short of its own refusal mark (a drape
    # can stay tight for seconds, then fit), before the stretchiest knit: the least stretchy
    # fabric that fits is the drape
    strain = _fit_strain(first)
    again = (getattr(first, "gave_up", False) and strain is not None
             and strain <= fab.strain_threshold + tuning.drape.too_tight)
    for k, name in enumerate(CLOSE_FIT_FABRICS):
        knit, last = get_fabric(name), k == len(CLOSE_FIT_FABRICS) - 1
        if last and again:
            say("sewing", 0.0, f"{said[-1]}: draping it in {fab.name} to the end")
            first = attempt(request, tuning, fabric_why)
            if _fits(first):
                return first
            said[0] = _how_it_fit(fab, first)
        why = (f"the pattern's fit: {'; '.join(said)}: cut with no ease there, it is a garment for a knit "
               f"(choose the fabric {fab.name} to see it in {fab.name})")
        # (with the parts found held sewn from a stretchier knit still: a knit top with rib cuffs)
        keep = {n: f for n, f in parts.items() if get_fabric(f).strain_threshold > knit.strain_threshold}
        say("sewing", 0.0, f"{said[-1]}: draping it again in {knit.name}, a knit"
                           + (f", {_in_fabrics(keep, 'sewn from')}" if keep else ""))
        out = attempt(request.model_copy(update={"fabric": knit.name}), tuning if last else quick, why, keep or None)
        tried.append((knit, out))
        if _fits(out):
            out[1]["warnings"].append(f"draped in {knit.name}, a knit" + (f", {_in_fabrics(keep, 'sewn from')}"
                                                                          if keep else "") + f": {'; '.join(said)}")
            return out
        if isinstance(out, Exception) and not _no_fit(out):
            break  # (a knit that fails for another reason: a stretchier one would too)
        said.append(_how_it_fit(knit, out))
    # no fabric fits: the first fabric's drape, or the stretchiest knit's tight one, or the refusal
    knits_how = "; ".join(f"in {knit.name}, a knit, " + (f"it failed ({o})" if isinstance(o, Exception) else
                                                        f"it is tight too (stretched {100 * o[1]['strain']['max']:.0f} %)")
                          for knit, o in tried)
    if not isinstance(first, Exception):
        first[1]["warnings"].append(f"{knits_how}: this is the drape in {fab.name}")
        return first
    draped = [(knit, o) for knit, o in tried if not isinstance(o, Exception)]
    if draped:  # refused in the first fabric, tight in a knit: the stretchiest knit's drape
        draped[-1][1][1]["warnings"].append(f"draped in {draped[-1][0].name}, a knit: {'; '.join(said)}")
        return draped[-1][1]
    too = "".join(f" (in {knit.name} too: {o})" for knit, o in tried)
    first.args = (f"{first}{too}",) + tuple(first.args[1:])
    raise first


PART_KNIT = "stretch_knit"  # the fabric of the parts run_tryon finds held at the first fabric's limit
RIB_KNIT = "rib_knit"  # ... and of those parts where they are held in PART_KNIT too
PART_ROUNDS = 2  # drapes with more such parts in PART_KNIT at most (then at most one with some in RIB_KNIT)
PART_SHARE = 0.25  # ... and those parts at most this share of the garment's cloth (cuffs, bands, a hood)


def _panel_areas(spec: PatternSpec) -> dict[str, float]:
    """Each panel's flat area (m^2), by name."""
    from engine.pattern import geometry as geo

    rel = spec.properties.curvature_coords == "relative"
    return {n: abs(geo.signed_area(geo.outline(p, spec.scale, rel))) for n, p in spec.pattern.panels.items()}


def _tight_parts(out) -> list[str]:
    """The panels a drape (run_tryon's attempt: (result, report) or error) held at its fabric's limit."""
    return list(getattr(out, "tight_panels", None) or []) if isinstance(out, Exception) else list(out[0].held)


def _in_fabrics(parts: dict[str, str], verb: str = "in") -> str:
    """The parts by fabric, in words: "'cuff_l', 'cuff_r' sewn from rib_knit, a knit, and
    'hood' sewn from stretch_knit, a knit" (verb "in": "... in rib_knit, a knit")."""
    by: dict[str, list[str]] = {}
    for n, f in parts.items():
        by.setdefault(f, []).append(n)
    return ", and ".join(f"{_listed(dict.fromkeys(ns))} {verb} {f}, a knit" for f, ns in by.items())


def _listed(parts: dict) -> str:
    names = [f"'{n}'" for n in parts]
    return ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")


def part_strains(model, x: np.ndarray, panel_fabrics: dict[str, str]) -> dict:
    """The strain of the parts in another fabric, against their own rest lengths: the report's
    strain max reads each spring against its own fabric's limit (ClothModel.allow), as the share of
    the garment fabric's threshold; this says how far the knit parts themselves stretched."""
    from engine.cloth.model import FLEXION, spring_strains

    if model.allow is None:
        return {}
    s, strain = spring_strains(model, x)
    allow = model.allow[model.kind != FLEXION]
    out = {}
    for name in sorted(set(panel_fabrics.values())):
        fab = get_fabric(name)
        own = np.isclose(allow, (1.0 + fab.strain_threshold) / (1.0 + model.fabric.strain_threshold))
        if own.any():
            real = (1.0 + strain[own]) * allow[own] - 1.0
            out[name] = {"max": float(real.max()), "threshold": fab.strain_threshold}
    return out


HELD_UNSETTLED = 0.9  # a drape that did not settle with the strain guard acting in this share of its last steps ...


def _fits(out) -> bool:
    """Whether a drape (run_tryon's attempt: (result, report) or error) fits its fabric: not tight,
    and at rest -- a drape that never settled, the strain guard holding it at the fabric's limit
    (HELD_UNSETTLED) all along, is a garment at its limit shaking against the body (mean_female
    83_004 and 89_002 in cotton, polished under the tight mark: 5.8-5.9 % for the whole 6 s budget;
    each fits jersey and settles)."""
    if isinstance(out, Exception) or out[1]["tight"]:
        return False
    rep = out[1]
    return rep.get("settled", True) or (rep["strain"].get("guard_share") or 0.0) < HELD_UNSETTLED


def _no_fit(err: Exception) -> bool:
    """Whether a SimulationError says the garment does not fit (refused as too small, or its seams
    stalled beside a part stretched far past the fabric) rather than that it could not be sewn."""
    return getattr(err, "stretched_at", None) is not None or getattr(err, "small_part", None) is not None


def _fit_strain(out) -> float | None:
    """The strain a drape ended or was refused at (a stall: its most stretched part's), or None."""
    if not isinstance(out, Exception):
        return out[1]["strain"]["max"]
    return getattr(out, "strain", None) if getattr(out, "stretched_at", None) is not None else \
        getattr(out, "small_part", None)


def _how_it_fit(fab, out) -> str:
    """How a drape in `fab` did not fit, in words."""
    strain = _fit_strain(out)
    allows = f"{fab.name} allows {100 * fab.strain_threshold:.0f} %"
    if getattr(out, "small_part", None) is not None:
        return f"in {fab.name} its seams stopped closing beside cloth stretched {100 * strain:.0f} % where {allows}"
    if not isinstance(out, Exception) and not out[1]["tight"]:  # (not _fits: did not come to rest)
        return f"in {fab.name} it did not come to rest, held at the fabric's limit ({100 * strain:.1f} % where {allows})"
    how = f"{100 * strain:.0f} % stretched" if strain is not None else "too stretched"
    ended = "stayed" if getattr(out, "gave_up", False) else "ended"
    return f"in {fab.name} it {ended} {how} where {allows}"


def _run_tryon(body: Body, spec: PatternSpec, request: TryOnOptions, tuning: Tuning, fabric_why: str, *,
               place=None, source: str = "pattern", progress: Progress | None = None, observer=None,
               lift=None, panel_fabrics: dict[str, str] | None = None,
               drop: tuple[float, float, float] | None = None) -> tuple[DrapeResult, dict]:
    """run_tryon in the request's fabric (named, and why); panel_fabrics: panel name -> the fabric
    of the parts sewn from another (engine.scene.drape.sew_and_drape). A pattern file whose
    crotch seams stall because its rise is shorter than the body's crotch from where its top is
    placed (engine.scene.drape: err.crotch), trousers alone or with a waistband (every other panel
    under the armpits: _below_arms), is placed again that much lower, at most CROTCH_DROP -- where a wearer would wear it -- and sewn
    once more (drop: (m lower, its rise m, the body's from the placed top m))."""
    from engine.collide.bvh import MeshBVH, penetration_stats

    progress = progress or (lambda *a: None)
    if lift is not None and request.collision != "image":
        raise InputError("dressing with the arms raised and lowering them needs the image-space collision "
                         "(--collision image)")
    loaded, body = body, (lift.raised if lift is not None else body)  # the body sewn and draped on
    fab = get_fabric(request.fabric)
    sew_note = None
    if tuning.sew.friction is None:
        friction, sew_note = sewing_friction(body, fab)
        tuning = replace(tuning, sew=replace(tuning.sew, friction=friction))
    t_all = time.perf_counter()
    # the body's BVH for the exact penetration figures at the end, built on the other core while
    # this thread meshes and places the panels and renders the maps (its kernels release the GIL)
    bvh_pool = ThreadPoolExecutor(1, thread_name_prefix="body-bvh")
    bvh_job = bvh_pool.submit(MeshBVH, loaded.vertices, loaded.faces)
    bvh_pool.shutdown(wait=False)
    progress("meshing", 0.0, "meshing the panels")
    placement_note = None
    pattern_file = place is None  # a pattern file's placement (its own, or carried by landmarks)
    if not pattern_file and tuning.drape.polish_at is not None:
        # (a garment placed where it is worn is judged by how tight it ends -- rode_up, the size
        # chart's --size auto -- and polished, the sample scan's XS sleeveless shirt that rode 9 cm
        # up over the bust ended 5.6 % stretched instead of 6.3 %, and was accepted)
        tuning = replace(tuning, drape=replace(tuning.drape, polish_at=None))
    if place is None:
        from engine.garment.place import pattern_placement

        def inside(p):  # the placement's test of a pattern's own layout (against the body as loaded)
            return bvh_job.result().signed_distance(p, max_distance=0.1) < 0.0

        place, placement_note = pattern_placement(spec, body, inside)
    garment = build_garment(spec, h=request.h, place=place, source=source)
    if pattern_file:
        placement_note = _over_the_shoulders(garment, body, inside, placement_note)
    if drop is not None:
        garment.positions[:, 1] -= drop[0]
        said = (f"lowered {100 * drop[0]:.0f} cm: its rise, {100 * drop[1]:.0f} cm through the crotch, is shorter "
                f"than the body's {100 * drop[2]:.0f} cm from where it was placed, so it sits lower, as it would be worn")
        placement_note = f"{placement_note}; {said}" if placement_note else f"the pattern's own placement, {said}"
    plan = plan_maps(body, garment, request.texel, request.collision)
    floor = ground(body.vertices)  # (the feet do not move when the arms are raised and lowered)
    t0 = time.perf_counter()
    progress("maps", 0.0, "rendering collision maps" if request.collision == "image" else "building the BVH")
    collider, map_info = _body_collider(body, plan, request, tuning.cloth.tolerance)
    t_maps = time.perf_counter() - t0
    if lift is not None and observer is not None:  # a live view shows the raised body while sewing
        shown, watch = [False], observer

        def observer(stage, x, tri, bv):
            if not shown[0] and bv is None:
                bv, shown[0] = lift.raised.vertices, True
            watch(stage, x, tri, bv)
    bvh = bvh_job.result()  # (done before the solver and its query helper thread start)
    held, held_note = attachment(garment, body)
    # (a pattern file's own layout: GarmentCode's reaches its body's hands; the catalogue's and a
    # DXF's placements start clear of the arms)
    lower = lower_labelled(spec) if pattern_file else frozenset()
    # (the hanging arms, and those arms whole: found once, for both of their uses)
    arms = _hanging(body, whole=True) if pattern_file else None
    passing = _arms_passed(body, garment, plan, request, tuning.cloth.tolerance, lower=lower,
                           arm=arms[0] if arms is not None else None) if pattern_file else None
    if lift is not None:  # (the trunk-side meeting needs the body's BVH, which a lift's sewing has not)
        arms = None
    if passing is not None:
        map_info["passed_through"] = passing.why
    again = None
    try:
        res = sew_and_drape(garment, collider, request, tuning, progress, observer=observer, attachment=held,
                            body_bvh=bvh if lift is None else None, pass_through=passing,
                            floor=floor, panel_fabrics=panel_fabrics, arms=arms)
    except SimulationError as e:
        # (trousers alone, or with a waistband -- no panel above the armpits: a jumpsuit lowered
        # would hang its bodice off the shoulders)
        alone = pattern_file and drop is None and bool(lower) and _below_arms(garment, body, lower)
        again = _crotch_drop(e, body) if alone else None
        if again is None:
            _carried_hint(e, placement_note, body)
            _hand_hint(e, body)
            raise
    finally:
        collider.release()  # (the map collider's query helper thread)
    if again is not None:
        progress("sewing", 0.0, f"the rise is too short for where the top was placed: sewing it again "
                                f"{100 * again[0]:.0f} cm lower")
        try:
            return _run_tryon(loaded, spec, request, tuning, fabric_why, source=source, progress=progress,
                              observer=observer, lift=lift, panel_fabrics=panel_fabrics, drop=again)
        except SimulationError as e:
            e.lowered = again  # (run_tryon's next fabric is placed as low)
            raise
    res.spec, res.lowered = spec, drop
    if passing is not None and res.released is False:
        map_info["passed_through"] += ("; the drape did not settle, so the whole body never took over: "
                                       "an arm may pass through the cloth (look at the pictures)")
    if lift is not None:
        from engine.scene.arms import lower_arms

        plan_l = plan_maps(lift.rigged, garment, request.texel, request.collision)
        res = lower_arms(lift, res, request, tuning, plan_l, progress=progress, observer=observer)
        body = loaded
    # (as placed, but no lower than the ground: a layout that put a hem under the feet has it end
    # on the floor, neither risen nor bunched)
    placed = garment.positions.copy()
    placed[:, 1] = np.maximum(placed[:, 1], floor)
    # (a lower garment's panels laid out in rings above the waist -- over the head -- fall by
    # design: where the pattern has others, those say whether it slid or fell off the shoulders)
    judged = judged_part(garment, lower) if pattern_file else None
    shift = hang_shift(placed, res.positions, res.vertex_map, judged)
    areas = _panel_areas(spec)
    shoulder_y = _world_height(body, "shoulder_height")
    shrunk = shortest_panel(garment, res, placed,
                            skip={n for n, a in areas.items() if a < SMALL_PART * sum(areas.values())}
                            | over_the_head(garment, res, shoulder_y))
    vm = res.vertex_map
    part = judged is not None and judged.any() and vm is not None and len(vm) == len(judged)
    fell = fell_off(garment.positions[judged] if part else garment.positions,
                    res.positions[vm[judged]] if part else res.positions, shoulder_y, same=bool(part))
    if slid(shift, SLID_OFF):  # settled, but not on the body: never written as a result
        raise _slid(body, res, shift, placement_note, crossing_hint(garment))
    if not pattern_file and rode_up(shift, res.strain_max, fab):  # (a pattern file's layout may rise into place)
        raise _rode_up(res, shift, fab)
    pen = penetration_stats(body.vertices, body.faces, res.positions, bvh=bvh)
    iters = sum(res.iterations.values())
    tc, tk = res.timing["cloth_total"], res.timing["collision_total"]
    report = {
        "body": body.name, "garment": source, "fabric": request.fabric, "fabric_why": fabric_why,
        **({"panel_fabrics": dict(panel_fabrics)} if panel_fabrics else {}),
        "collision": request.collision,
        "cloth_vertices": int(len(res.positions)),
        "cloth_vertices_unsewn": int(garment.n_vertices),
        "iterations": int(iters),
        "iterations_by_stage": res.iterations,
        "dt_ms": res.dt * 1000, "dt_bound_ms": res.model.dt_bound * 1000,
        # collisions are checked every this many steps, so a collision ms per iteration is that
        # of an average step, not of a step that checks
        "collision_every_steps": res.collide_every,
        "ms_per_iteration": {"cloth": 1000 * tc / max(iters, 1), "collision": 1000 * tk / max(iters, 1),
                             "total": 1000 * (tc + tk) / max(iters, 1)},
        "wall_seconds": {"maps": t_maps, **{k: v for k, v in res.timing.items() if not k.endswith("_total")},
                         "total": time.perf_counter() - t_all},
        "penetration_mm": {"max": pen["max"] * 1000, "p99": pen["p99"] * 1000,
                           "count_inside": int(pen["count_inside"])},
        # the guard holds strain at threshold + guard by moving positions (never into the body):
        # guard_share says how much of the fit it held in the end (0: none of the last steps)
        "strain": {"max": res.strain_max, "threshold": fab.strain_threshold, "guard": res.strain_guard,
                   "guard_share": res.guard_share,
                   "at_m": [round(float(c), 4) for c in most_stretched(res.positions, res.model)[1]],
                   **({"parts": part_strains(res.model, res.positions, panel_fabrics)} if panel_fabrics else {})},
        "seam_gap_mm": {"max": res.seam_gap_max * 1000, "snapped": res.snapped},
        "shift_mm": {k: v * 1000 for k, v in shift.items()},
        "sharp_folds": sharp_folds(res.positions, res.triangles),
        "kinetic_energy_j": res.kinetic_energy,
        "settled": bool(res.settled),
        "collision_maps": map_info,
        "left_out": plan.left_out,
        "self_contact": {"on": bool(res.self_contact[0]), "why": res.self_contact[1]},
        **({"exact_finish": res.finish} if res.finish else {}),
        **({"stood_out": res.stood_out} if res.stood_out else {}),
        **({"placement": placement_note} if placement_note else {}),
        **({"attachment": held_note} if held_note else {}),
        "sew_friction": {"scale": float(tuning.sew.friction),
                         "why": sew_note or ("asked for" if tuning.sew.friction else "the panels slide into place")},
        "tight": bool(res.strain_max > fab.strain_threshold + TIGHT),
        "warnings": garment.warnings + hang_warnings(shift, crossing_hint(garment), shrunk, fell) + [
            w for w in [held.elastic.note if held is not None and held.elastic is not None else None,
                        stands_off(garment, body, res.positions, res.vertex_map, held, bvh)] if w] + fit_warnings(res.strain_max, fab, res.settled,
                                                                           tuning.drape.budget, pattern_file),
    }
    if lift is not None:
        report["arms_lowered"] = {"degrees": lift.degrees, "arm_gap_cm": {"as_loaded": 100 * lift.gap_loaded,
                                                                           "raised": 100 * lift.gap_raised},
                                  "why": lift.describe(), **res.lowering}
    return res, report


def dress_request(body: Body, request: TryOnRequest, tuning: Tuning = Tuning(), *, progress: Progress | None = None,
                  observer=None, note=None, label: str | None = None) -> tuple[DrapeResult, dict]:
    """Dress `body` in request.garment, in request.size (auto: chosen from the body's girths, then
    by draping: engine.scene.garments.dress_in_size), as the command line and the service do.
    note(size, why, next size): called before --size auto dresses a larger size. label: the
    garment's name in the report, in place of the pattern file's name (default: the catalogue's,
    or the pattern file's)."""
    def dress(spec, place, name, **kw):
        source = name.replace(Path(request.garment).name, label, 1) if label else name
        return run_tryon(body, spec, request, tuning, place=place, source=source, progress=progress,
                         observer=observer, **kw)

    return dress_in_size(request.garment, body, request.size, dress, note=note,
                         dxf={"units": request.units, "assembly": request.assembly})


def _body_collider(body: Body, plan: TryOnPlan, request: TryOnOptions, tolerance: float):
    """The collider the garment is dressed against, and what the report says of it."""
    if request.collision == "image":
        from engine.collide.collider import MapCollider
        from engine.collide.maps import render_body_maps

        maps = render_body_maps(body, texel=request.texel, window=plan.window, segments=plan.segments,
                                tol=tolerance)
        return MapCollider(maps), {"maps": maps.names, "texel_mm": request.texel_mm,
                                   "size": [[int(a), int(b)] for a, b in maps.layout[:, :2]]}
    from engine.collide.bvh import ObjectSpaceCollider

    return (ObjectSpaceCollider(body.vertices, body.faces, tolerance=tolerance),
            {"maps": [], "bvh_triangles": int(len(body.faces))})


EXEMPT_BELOW = 0.10  # m: a panel this far under the armpits (all of it) is a lower garment's ...
EXEMPT_AXIS = 0.4  # m: ... all of it that lies this near the body's vertical axis ...
# ... but for its highest tenth there: a circle skirt's half laid flat before the body is a ring
# whose ends rise to the chest beside the waist (mean_female 61_009's skirt, mid-height 0.79 m,
# rose to 1.37 m: its side seams caught on the arms)
EXEMPT_TOP = 90
LOWER_LABEL = "leg"  # GarmentCode's segmentation label of a lower garment's panels (its meta_garment)


CROTCH_DROP = 0.15  # m: a lower garment whose rise is short is placed at most this much lower (_crotch_drop)


def _crotch_drop(err: Exception, body: Body) -> tuple[float, float, float] | None:
    """(m lower, the rise m, the body's crotch length from the placed top m) that lets the rise
    of a lower garment whose crotch seams stalled short (err.crotch: its cloth through the crotch
    shorter than the body's from where its top hangs) reach round -- trousers GarmentCode drafts
    for f_smpl with a rise 19-27 cm shorter than that body's from 2.6 cm under its waist stalled
    4-10 cm open; a wearer wears them lower. None where CROTCH_DROP lower is not enough."""
    from engine.scene.drape import crotch_fit_drop

    short = getattr(err, "crotch", None)
    if short is None:
        return None
    reach, y_top, xc, body_len = short
    drop = crotch_fit_drop(body.vertices, body.faces, reach, y_top, xc, CROTCH_DROP)
    return None if drop is None else (drop, reach, body_len)


def _below_arms(garment, body: Body, lower: frozenset[str]) -> bool:
    """Whether every panel of the placed garment but the lower garment's (`lower`: its trousers
    or skirt) lies under the body's armpits: a waistband, not a bodice."""
    other = ~np.isin(garment.panel_names, list(lower))[garment.panel]
    if not other.any():
        return True
    armpit = _armpit_y(body)
    return bool(np.isfinite(armpit)) and float(garment.positions[other, 1].max()) < armpit


def judged_part(garment, lower: frozenset[str]) -> np.ndarray:
    """(placed vertices,) bool: the cloth whose top and bulk say whether a pattern file's drape
    slid or fell off the shoulders -- the panels not labelled a lower garment's (lower_labelled:
    a skirt laid out in a ring above its head falls by design); where every panel is, a skirt or
    trousers alone, its waist ('lower_interface', which the attachment holds: f_smpl 109_013's
    circle skirt, laid out reaching past the shoulders and hanging at the waist, had "fallen off
    the shoulders" and "slid 38 cm"); all False where it has none."""
    judged = ~np.isin(garment.panel_names, list(lower))[garment.panel]
    waist = garment.labelled.get("lower_interface")
    if not judged.any() and waist is not None and len(waist):
        judged[waist] = True
    return judged


def lower_labelled(spec: PatternSpec) -> frozenset[str]:
    """The panels a pattern labels a lower garment's (LOWER_LABEL): GarmentCode labels a skirt's or
    trousers' panels so, however it lays them out -- a circle skirt or a flounce laid flat in a
    ring reaches up past the arms, far above the waist it hangs from."""
    return frozenset(n for n, p in spec.pattern.panels.items() if p.label == LOWER_LABEL)


def _hanging(body: Body, whole: bool = False):
    """engine.body.hanging.hanging_arms of the body, under its armpits."""
    from engine.body.hanging import hanging_arms

    return hanging_arms(body, _armpit_y(body), whole)


def _arms_passed(body: Body, garment, plan: TryOnPlan, request: TryOnOptions, tolerance: float,
                 lower: frozenset[str] = frozenset(), arm: np.ndarray | None = None):
    """The PassThrough (engine.collide.collider) of a garment with panels that hang wholly below
    the arms (skirts, trousers, a dress's skirt), or None: their cloth passes through the arms
    that hang beside them while the seams close and until the drape first settles, as in
    GarmentCode's own simulator (engine.body.hanging); then it meets the whole body.
    lower: panels the pattern labels a lower garment's (lower_labelled): below the arms
    wherever their layout's top lies, if their middle is. arm: _hanging(body), where found already."""
    if request.collision != "image" or (plan.segments is not None and not any("arm" in s for s in plan.segments)):
        return None
    armpit = _armpit_y(body)
    arm = _hanging(body) if arm is None else arm  # (None where the armpits cannot be found)
    if arm is None:
        return None

    # a lower garment's panels: under the armpits, sewn together into pieces (a skirt's ring, a
    # trouser leg, a cuff) centred nearer the trunk than an arm (a cuff's ring round the wrist is
    # an arm's; a wide skirt laid out in a ring reaches the hands, but its middle is the hips).
    # A panel's height is that of its part near the body's axis (the outer tiers of a wide skirt
    # rise towards their edges, far beside the body) and of its middle.
    n = len(garment.panel_names)
    x = garment.positions
    near = np.hypot(x[:, 0], x[:, 2]) < EXEMPT_AXIS
    top = np.full(n, -np.inf)
    for i in np.unique(garment.panel[near]):
        top[i] = np.percentile(x[near & (garment.panel == i), 1], EXEMPT_TOP)
    mid = np.bincount(garment.panel, weights=x[:, 1], minlength=n) / np.maximum(np.bincount(garment.panel, minlength=n), 1)
    labelled = np.isin(garment.panel_names, list(lower))
    below = ((top < armpit - EXEMPT_BELOW) | labelled) & (mid < armpit - EXEMPT_BELOW)
    if not below.any():
        return None
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pp = garment.panel[garment.seams] if len(garment.seams) else np.zeros((0, 2), int)
    pp = pp[below[pp].all(axis=1)]
    _, piece = connected_components(coo_matrix((np.ones(len(pp)), (pp[:, 0], pp[:, 1])), shape=(n, n)),
                                    directed=False)
    lower = np.zeros(n, bool)
    tree = cKDTree(body.vertices)
    for c in np.unique(piece[below]):
        panels = np.flatnonzero((piece == c) & below)
        middle = garment.positions[np.isin(garment.panel, panels)].mean(axis=0)
        lower[panels] = not arm[tree.query(middle)[1]]
    if not lower.any():
        return None
    from engine.collide.collider import PassThrough
    from engine.collide.maps import render_body_maps

    # that cloth passes through the body above where a lower garment is worn too: a circle skirt
    # laid flat in a ring reaches over the chest and head, and its side seams close through them
    # (they stalled across the chest: f_smpl 97_006); worn, it hangs from the waist.
    # Only where labelled cloth lies above that height and all the passing cloth the pattern does
    # not label a lower garment's lies under it (a low-backed bodice's back, under the arms by its
    # height near the axis, fell through the torso: mean_female 83_005)
    cut = armpit - EXEMPT_BELOW
    passing, mine, y = lower[garment.panel], labelled[garment.panel], garment.positions[:, 1]
    above = body.vertices[:, 1] > cut
    if not (y[passing & mine] >= cut).any() or (y[passing & ~mine] >= cut).any():
        above[:] = False
    arm = arm | above
    if plan.segments is None:
        keep = ~arm[body.faces].any(axis=1)
        without = render_body_maps(Body(body.vertices, body.faces[keep]), texel=request.texel, window=plan.window,
                                   tol=tolerance, extent=np.unique(body.faces))  # (the whole body's grid)
    else:  # the hanging parts labelled no segment's: every map draws the rest (an arm not hanging whole)
        seg = np.asarray(body.segments).copy()
        seg[arm] = 255
        without = render_body_maps(Body(body.vertices, body.faces, segments=seg), texel=request.texel,
                                   window=plan.window, tol=tolerance, segments=plan.segments)
    names = ", ".join(garment.panel_names[i] for i in np.flatnonzero(lower))
    also = f" and the body from {100 * EXEMPT_BELOW:.0f} cm under the armpits up" if above.any() else ""
    return PassThrough(without, lower[garment.panel],
                       f"{names}: passed through the hanging arms{also}"
                       " while sewn "
                       "and until the drape first settled "
                       "(as in GarmentCode's simulator: a skirt's side seams otherwise catch on the hands), "
                       "then draped against the whole body")


def _slid(body: Body, res: DrapeResult, shift: dict, placement_note: str | None,
          crossing: str | None = None) -> SimulationError:
    floor = float(body.vertices[:, 1].min())
    err = SimulationError(
        f"the garment slid {-100 * shift['top']:.0f} cm down the body (its top ended "
        f"{res.positions[:, 1].max() - floor:.2f} m above the floor): it did not stay where it was placed -- "
        "it is too large for this body, or its seams did not close around it; try a smaller size, or "
        "check the pattern's panels" + (f" ({crossing})" if crossing else ""))
    err.positions, err.triangles = res.positions.copy(), res.triangles  # for a picture
    err.too_large = True  # (engine.scene.garments: --size auto tries a smaller one)
    _carried_hint(err, placement_note, body, slid=True)
    return err


def rode_up(shift: dict, strain: float, fabric) -> bool:
    """Whether a garment placed where it is worn rode up: its bulk rose RODE_UP and it ended tight
    (stretched past the fabric's threshold + TIGHT)."""
    return shift["bulk"] > RODE_UP and strain > fabric.strain_threshold + TIGHT


def _rode_up(res: DrapeResult, shift: dict, fab) -> SimulationError:
    """A garment placed where it is worn (the catalogue, a DXF) that rose RODE_UP and ended tight: too small
    round the body there, it was pushed up to where the body is narrower (an XS shirt over a
    97.5 cm bust rose 9 cm and ended 6 % stretched, where it would be 19 % round the bust)."""
    err = SimulationError(
        f"the garment is too small for this body: it rode {100 * shift['bulk']:.0f} cm up from where it is worn "
        f"and is stretched {100 * res.strain_max:.0f} % where {fab.name} allows "
        f"{100 * fab.strain_threshold:.0f} % there; try a larger size")
    err.positions, err.triangles = res.positions.copy(), res.triangles  # for a picture
    err.too_small = True  # (engine.scene.garments: --size auto tries a larger one)
    err.strain = res.strain_max
    return err


def _carried_hint(err: Exception, placement_note: str | None, body: Body, slid: bool = False) -> None:
    """A GarmentCode pattern carried onto another body by its landmarks (pattern_placement) whose
    seams did not close, or that slid down the body: on a body whose girths differ from the mean
    body's by more than OTHER_BODY the error starts by saying the pattern is for another body,
    both bodies' girths named; else it adds that the placement may be why."""
    from engine.body.measure import measure
    from engine.garment.place import CARRIED, CARRIED_HINT, GARMENTCODE_GIRTHS

    if placement_note != CARRIED or not (slid or getattr(err, "open_top", None) is not None):
        return
    try:
        m = measure(body)
        mine = {k: getattr(m, k) for k, _ in GARMENTCODE_GIRTHS}
    except TryonError:
        mine = {}
    if mine and max(abs(mine[k] - ref) for k, ref in GARMENTCODE_GIRTHS) > OTHER_BODY:
        def girths(g):
            return ", ".join(f"{k} {100 * v:.0f}" for k, v in g) + " cm"

        err.args = (f"this pattern is for another body: GarmentCode laid it out round its mean body "
                    f"({girths(GARMENTCODE_GIRTHS)}), and this body's are {girths(mine.items())} -- make the "
                    f"pattern in GarmentCode for this body's measurements ({err})",) + tuple(err.args[1:])
    else:
        err.args = (f"{err}. {CARRIED_HINT}",) + tuple(err.args[1:])


OTHER_BODY = 0.08  # m: a girth this far from the mean body's: the pattern is for another body

AT_WRIST = 0.97  # open seams this far along the arm from the acromion to the wrist, or past it ...
NEAR_ARM = 0.12  # m: ... within this of that line (produced past the wrist) lie at the hand


def _hand_hint(err: Exception, body: Body) -> None:
    """Seams that stayed open at the wrists or past them, over the hands (GarmentCode's sleeves run
    past the wrist, their end narrower than the hand: f_smpl 67_013's 17 cm end 6-9 cm past
    it): the error says so, and what would close them."""
    from engine.body.measure import measure

    pts = getattr(err, "open_points", None)
    if pts is None or not len(pts):
        return
    try:
        lines = measure(body).arm_lines
    except TryonError:
        return
    p = pts - [0.0, float(body.vertices[:, 1].min()), 0.0]  # (measured from the floor)
    at = np.zeros(len(p), dtype=bool)
    for a, w in lines:
        d = w - a
        t = (p - a) @ d / max(float(d @ d), 1e-12)
        off = np.linalg.norm(p - (a + t[:, None] * d), axis=1)
        at |= (t >= AT_WRIST) & (off < NEAR_ARM)
    if at.mean() < 0.5:
        return
    from engine.scene.drape import OPEN_WHY

    said = str(err).removesuffix(OPEN_WHY).rstrip()
    err.args = (f"{said} They lie at the wrists or past them, over the hands ({at.sum()} of {len(p)} open "
                "pairs): a sleeve or cuff that reaches the hand, narrower than the hand, cannot close round it "
                "-- shorter sleeves, or wider sleeve ends, would",) + tuple(err.args[1:])


# x the fabric's friction while sewing on a body whose arms hang closer to its torso than
# ARM_GAP_OK: without it the straps slide off the shoulders down the arm, which no longer falls
# away at 45 degrees (not on every body: friction for all is worse)
ARMS_CLOSE_SEW_FRICTION = 1.0


# a fabric whose strain threshold is at least this is worn stretched (elastane knits): friction
# holds it where it is sewn, as it holds leggings up (without it the stretched cloth slides down the
# body, while it is sewn, to where it is least stretched)
WORN_STRETCHED = 0.20


def with_fabric(request: TryOnOptions, spec: PatternSpec) -> tuple[TryOnOptions, str]:
    """The request with its fabric named -- the user's, else the pattern's own, else
    DEFAULT_FABRIC -- and why."""
    from engine.cloth.fabrics import DEFAULT_FABRIC

    if request.fabric is not None:
        return request, "asked for"
    own = spec.tryon.fabric if spec.tryon is not None else None
    if own:
        get_fabric(own)  # (a pattern file's unknown fabric: InputError naming the fabrics)
        why = f"the pattern's: {spec.tryon.fabric_why}" if spec.tryon.fabric_why else "the pattern's own"
        return request.model_copy(update={"fabric": own}), why
    return request.model_copy(update={"fabric": DEFAULT_FABRIC}), "the default"


def sewing_friction(body: Body, fabric=None) -> tuple[float, str | None]:
    """(friction scale while sewing, why) for this body and fabric: see WORN_STRETCHED and
    ARMS_CLOSE_SEW_FRICTION."""
    from engine.body.measure import ARM_GAP_BELOW, ARM_GAP_OK, measure

    if fabric is not None and fabric.strain_threshold >= WORN_STRETCHED:
        return 1.0, (f"{fabric.name} is worn stretched: friction holds it where it is sewn (without it the "
                     "cloth slides down the body to where it is least stretched)")
    try:
        m = measure(body)
    except InputError:  # a body the measurements cannot read: the default
        return 0.0, None
    if not m.arm_gap < ARM_GAP_OK:
        return 0.0, None
    return ARMS_CLOSE_SEW_FRICTION, (f"the arms hang {100 * m.arm_gap:.1f} cm from the torso "
                                     f"{100 * ARM_GAP_BELOW:.0f} cm below the armpits: friction holds "
                                     "the straps on the shoulders while sewing")


TOP_DROP = 0.10  # m: a garment whose top ends this far below where it was placed slid down the body
# m: ... and this far, it came off it: an error, not a result (it may meet every other bar)
SLID_OFF = 0.25
FELL = 0.15  # m: a garment placed over the shoulders whose top ends this far below them fell off them
OVER_SHOULDERS = 0.05  # m: (placed over them: its top at least this near their height ...
OVER_AXIS = 0.4  # m: ... this near the body's vertical axis: a wide skirt laid flat in a ring
# rises above the shoulders 1.2-2.2 m to the side, and is worn at the waist)
SIDE_OF_AXIS = 0.03  # m: (fell_off: cloth this far to one side of the axis is that shoulder's)
RODE_UP = 0.06  # m: a catalogue garment whose bulk rose this far and ended tight is too small (_rode_up)
HEM_RISE = 0.15  # m: ... whose lowest point ends this far above its placed height bunched up ...
PANEL_TALL = 0.15  # m: ... where a panel placed at least this tall ...
BUNCHED = 0.6  # ... hangs shorter than this share of the length it can hang (hang_warnings) ...
HUNG_FROM = 0.03  # m: ... reaching from its highest seam (sewn to none: its vertices this near its top)
ACROSS_SHARE = 0.25  # ... of those across it at least this share of the longest as long
# (a part under this share of the garment's cloth lies as the body under it has it lie -- a collar
# along a deep V, a flounce round a wrist on a sloping arm, no hanging length to judge: the
# garment bunched up only where a larger panel hangs short)
SMALL_PART = 0.05
TIGHT = 0.01  # a drape stretched past the fabric's threshold by more than this is reported tight
# (issue 3's quality limit; the strain guard holds a garment that fits at threshold + 0.5 %, a knit 0.3 %)
# a pattern file too tight for the default fabric is draped again in these knits in turn: a
# cotton jersey, then one with elastane (GarmentCode cuts bands and cuffs, and some bodices
# below the waist, smaller round than the body where they sit)
CLOSE_FIT_FABRICS = ("jersey", "stretch_knit")


def fit_warnings(strain: float, fabric, settled: bool, budget: float, pattern_file: bool = False) -> list[str]:
    """Warnings about a drape that ended but does not fit well: stretched past the fabric's
    limit by more than TIGHT (past DrapeTuning.too_tight it is refused instead), or not
    settled within the budget (s of simulated time). A pattern file has one size: the advice
    is to grade it larger, not to pick a larger size."""
    out = []
    if strain > fabric.strain_threshold + TIGHT:
        advice = PATTERN_SIZE_ADVICE if pattern_file else "try a larger size"
        out.append(f"the garment is tight: stretched {100 * strain:.0f} % where {fabric.name} allows "
                   f"{100 * fabric.strain_threshold:.0f} % ({advice})")
    if not settled:
        out.append(f"the drape did not settle within {budget:g} s of simulated time: the cloth may "
                   "still be moving in the pictures")
    return out


def hang_shift(placed: np.ndarray, draped: np.ndarray, vertex_map: np.ndarray | None = None,
               judged: np.ndarray | None = None) -> dict[str, float]:
    """How far (m, up positive) the garment's highest and lowest points moved in height from the
    placement to the drape, and its bulk: the median vertex's move (through vertex_map, placed
    vertex -> draped; without one, the top's). A garment hanging on the body moves a few
    centimetres; one that slid off or collapsed moves far more, its bulk with it.
    judged: (placed vertices,) bool -- the part whose top and bulk are measured (with vertex_map;
    a dress's bodice: its skirt laid out in a ring above its head falls by design), None: all."""
    ok = vertex_map is not None and len(vertex_map) == len(placed)
    part = judged if ok and judged is not None and judged.any() else np.ones(len(placed), bool)
    p = placed[part]
    d = draped[vertex_map[part]] if ok else draped
    top = float(d[:, 1].max() - p[:, 1].max())
    bulk = float(np.median(d[:, 1] - p[:, 1])) if ok else top
    return {"top": top, "hem": float(draped[:, 1].min() - placed[:, 1].min()), "bulk": bulk}


def slid(shift: dict[str, float], drop: float) -> bool:
    """Whether a drape's top ended `drop` (m) below where it was placed with its bulk at least
    half as far down: a collar or hood placed standing that folds down drops the top alone
    (GarmentCode places a standing collar 10 cm above where it lies; the dress below rose 8 cm)."""
    return shift["top"] < -drop and shift.get("bulk", shift["top"]) < -0.5 * drop


def sharp_folds(positions: np.ndarray, triangles: np.ndarray, degrees: float = 150.0) -> dict:
    """Edges where the cloth folds back on itself: the normals of the two faces sharing an edge
    more than `degrees` apart. Compare like garments (docs/tuning.md has typical counts)."""
    import trimesh

    angles = trimesh.Trimesh(np.asarray(positions, dtype=np.float64), np.asarray(triangles), process=False,
                             validate=False).face_adjacency_angles
    return {"count": int((angles > np.radians(degrees)).sum()), "edges": int(len(angles)), "degrees": degrees}


def shortest_panel(garment: Garment, res: DrapeResult, placed: np.ndarray | None = None,
                   skip=()) -> tuple[float, str, float, float] | None:
    """Of the panels placed at least PANEL_TALL tall, the one whose drape is shortest for the
    length it can hang: (draped height / that length, its name, draped m, length m); None when no
    panel is that tall or the drape has no map from the garment's vertices. The length is the
    lesser of its placed height and how far its flat cloth reaches from where it hangs: the seams
    across it that end highest (within HUNG_FROM of the highest: a tier's to the tier above, a
    peplum's to the bodice's pieces, a bodice's shoulder seam; a seam dropping more than half its
    length runs down the side; a panel sewn only along such seams -- a collar on a V neckline --
    hangs from all of them; a panel sewn nowhere hangs from its top HUNG_FROM). A ring
    sector (a circle peplum, a ruffle tier) laid out flat 95 cm tall hangs its ring's width, 17 cm.
    placed: the garment's positions to measure from (default garment.positions); skip: panel
    names not judged (run_tryon: those under SMALL_PART of the cloth), nor are panels sewn to a
    panel above them and to one below (_joins: a band joining two parts); where every panel that
    tall is one of those, the ratio is inf: none bunched."""
    from scipy.spatial import cKDTree

    vmap = res.vertex_map
    if vmap is None or len(vmap) != len(garment.positions):
        return None
    best, skipped = None, []
    y0, y1 = (garment.positions if placed is None else placed)[:, 1], res.positions[vmap, 1]
    seams, sid = garment.seams, garment.seam_id
    for p, name in enumerate(garment.panel_names):
        on = garment.panel == p
        if not on.any():
            continue
        placed = float(np.ptp(y0[on]))
        if placed < PANEL_TALL:
            continue
        if name in skip:
            skipped.append(name)
            continue
        draped = float(np.ptp(y1[on]))
        across = []  # its seams across it (not side seams running down): (mean draped height, vertices, length)
        mine = on[seams]
        for s in np.unique(sid[mine.any(1)]):
            for side in seams[sid == s].T:  # (each edge of the stitch on this panel: a dart has two)
                v = side[on[side]]
                n = np.linalg.norm(np.diff(garment.uv[v], axis=0), axis=1).sum() if len(v) >= 2 else 0.0
                if len(v) >= 2 and np.ptp(y1[v]) <= 0.5 * n:
                    across.append((float(y1[v].mean()), v, n))
        # (not a stub of a seam: a ruffle tier 5 cm wide sewn 5.5 m round to the tier above has
        # side seams 3.5 cm long that lie level, higher than the gathered top it hangs from)
        longest = max((n for _, _, n in across), default=0.0)
        across = [(h, v) for h, v, n in across if n >= ACROSS_SHARE * longest]
        top = max((h for h, _ in across), default=None)
        if _joins(garment, on, y1):
            # (a band or a yoke joining the parts above and below it: its height is theirs to set,
            # not its own to hang -- mean_female 83_014's curved waistband, its lower edge
            # gathered into the shorts, stands out in a ruffle 10 cm tall, 18 cm long)
            skipped.append(name)
            continue
        if across:
            hung = np.concatenate([v for h, v in across if h >= top - HUNG_FROM])
        elif mine.any():  # sewn only along seams running down (a collar on a V neckline): from all of them
            hung = np.unique(seams[mine])
        else:
            hung = np.flatnonzero(on & (y1 >= y1[on].max() - min(HUNG_FROM, 0.2 * draped)))
        reach = float(cKDTree(garment.uv[hung]).query(garment.uv[on])[0].max())
        length = min(placed, reach)
        ratio = draped / max(length, 1e-9)
        if best is None or ratio < best[0]:
            best = (ratio, name, draped, length)
    if best is None and skipped:  # (every panel that tall is a small part: none hangs to judge)
        return (np.inf, skipped[0], 0.0, 0.0)
    return best


OVER_HEAD = 0.15  # m: a panel whose drape reaches this far above the shoulders lies over the head (over_the_head)


def over_the_head(garment: Garment, res: DrapeResult, shoulder_y: float) -> set[str]:
    """The panels whose drape reaches OVER_HEAD above the shoulders (a hood worn up): they rest
    on the head rather than hang from their highest seam, so shortest_panel does not judge them
    (f_smpl 269_022's hood, 35 cm tall over the head for the 61 cm it could hang, was called
    bunched). None where the body's shoulders are not measured."""
    vmap = res.vertex_map
    if not np.isfinite(shoulder_y) or vmap is None or len(vmap) != len(garment.positions):
        return set()
    y = res.positions[vmap, 1]
    return {n for p, n in enumerate(garment.panel_names)
            if (on := garment.panel == p).any() and float(y[on].max()) > shoulder_y + OVER_HEAD}


def _joins(garment: Garment, on: np.ndarray, y: np.ndarray) -> bool:
    """Whether the panel of the vertices `on` is sewn both to a panel that hangs above it and to
    one that hangs below it (each panel's mean height `y` against its draped top and bottom)."""
    pairs = garment.seams[on[garment.seams].sum(axis=1) == 1]
    other = np.unique(garment.panel[pairs[~on[pairs]]])
    means = [float(y[garment.panel == q].mean()) for q in other]
    top, bottom = float(y[on].max()), float(y[on].min())
    return any(m > top for m in means) and any(m < bottom for m in means)


def hang_warnings(shift: dict[str, float], crossing: str | None = None,
                  shrunk: tuple[float, str, float, float] | None = None, fell: float | None = None) -> list[str]:
    """What a drape that ended off where it was placed says; crossing: crossing_hint's, said with it.
    shrunk: shortest_panel's; a risen hem is bunching only where a panel also hangs shorter than
    BUNCHED of the length it can hang (GarmentCode stacks a jumpsuit's trousers below its bodice in the
    layout: they rise into place, hanging full length); None: the risen hem alone says so.
    fell: fell_off's (m below the shoulders), said first."""
    out = []
    if fell is not None:
        out.append(f"the garment fell off the shoulders: placed over them, its top ended {100 * fell:.0f} cm "
                   "below them, on one side at least (look at the pictures)")
    if slid(shift, TOP_DROP):
        out.append(f"the garment slid {-100 * shift['top']:.0f} cm down the body from where it was placed: "
                   "it may be too large for this body (try a smaller size)")
    if shift["hem"] > HEM_RISE and (shrunk is None or shrunk[0] < BUNCHED):
        panel = (f"; panel '{shrunk[1]}' hangs {100 * shrunk[2]:.0f} cm tall, {100 * shrunk[3]:.0f} cm long"
                 if shrunk is not None else "")
        out.append(f"the garment's lowest point rose {100 * shift['hem']:.0f} cm from where it was placed{panel}: "
                   "it bunched up instead of hanging (look at the pictures)")
    if out and crossing:
        out[0] += f" ({crossing})"
    return out


def crossing_hint(garment: Garment) -> str | None:
    """Where panels' outlines cross themselves (meshed joined at the crossings), what that may do to
    a drape: the parts beyond a crossing are joined to the rest only where the edges cross, and
    cannot hold up what hangs from them (GarmentCode draws a wide neckline past the armholes so,
    and the straps then let the bodice fall)."""
    names = sorted(garment.pinched)
    if not names:
        return None
    return (f"{pinched_outlines(names)}: the parts beyond a crossing hang from a point and may not hold (a "
            "neckline cut past the armhole) -- check those edges")


def write_pattern(out: Path, spec: PatternSpec | None) -> list[Path]:
    """pattern.json (the GarmentCode specification dressed: a catalogue garment as cut for this
    body and size) and pattern.svg (its panels, stitched edges in pairs) in `out`."""
    from engine.pattern.io import pattern_to_svg, save_pattern

    if spec is None:
        return []
    out.mkdir(parents=True, exist_ok=True)
    svg = out / "pattern.svg"
    svg.write_text(pattern_to_svg(spec))
    return [save_pattern(spec, out / "pattern.json"), svg]


def write_outputs(out: Path, body: Body, res: DrapeResult, report: dict, size: int = 700) -> list[Path]:
    """scene.glb, garment.obj, front/side/back.png, report.json, pattern.json/.svg in `out`."""
    from PIL import Image

    from engine.io.export import write_obj, write_scene_glb
    from engine.io.render import BODY_RGB, render_meshes

    out.mkdir(parents=True, exist_ok=True)
    paths = [write_scene_glb(out / "scene.glb", body.vertices, body.faces, [("garment", res.positions, res.triangles)]),
             write_obj(out / "garment.obj", res.positions, res.triangles)]
    meshes = [(body.vertices, body.faces, BODY_RGB), (res.positions, res.triangles, (0.27, 0.43, 0.75))]
    for view in ("front", "side", "back"):
        p = out / f"{view}.png"
        Image.fromarray(render_meshes(meshes, size=size, view=view)).save(p)
        paths.append(p)
    p = out / "report.json"
    p.write_text(json.dumps(report, indent=2))
    paths.append(p)
    return paths + write_pattern(out, res.spec)
