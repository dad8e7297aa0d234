"""The engine's tuning of each stage of a try-on (sewing, draping, walking): constants a user
rarely changes, frozen, one line each. The measurements behind the values are in docs/tuning.md
(keyed by these names); what a user sets is engine.scene.request."""

from __future__ import annotations

from dataclasses import dataclass

from engine.cloth.config import StepConfig
from engine.cloth.model import ClothParams
from engine.errors import InputError


@dataclass(frozen=True)
class SewTuning:
    """Sewing: each open stitch pair is pulled shut; a pair closer than weld_gap is welded."""

    weld_gap: float | None = None  # m: a pair this close is welded (None: half a cloth edge)
    tau: float = 0.02  # s: an open pair is pulled to close its gap in this time ...
    vmax: float = 3.0  # m/s: ... at most this fast
    far_gap: float = 0.2  # m: stitch pairs this far apart (90th percentile) are a flat layout round the body (GarmentCode's)
    far_retry_vmax: float = 1.5  # m/s: a flat layout whose seams stopped closing is sewn again, pulled this fast (0: not)
    retry_stall: float = 0.25  # s: ... judged stalled when its widest gap shrank < 1 mm over two windows this long
    damping: float = 20.0  # x the viscous damping while sewing (no flapping) ...
    far_damping: float = 1000.0  # ... or this for a flat layout, and for everything while calm_start lasts
    far_panel_damping: float = 0.0  # 1/s: a flat layout's panels damped toward their own mean motion
    far_together: bool = True  # a flat layout's open pairs all close in the time its widest gap needs at vmax
    calm_start: float = 0.05  # s: the strain a placement leaves relaxes without flinging the cloth
    friction: float | None = None  # x the fabric's friction (None: 0, or more on a body whose arms hang close)
    gravity: float = 1.0  # x g while sewing (a flared skirt without gravity opens into a disc)
    gravity_ramp: float = 0.3  # s: gravity grows from 0 to g over this long (no jolt as it starts)
    check_travel: float = 0.0015  # m: collisions are checked as often as the pull moves a point this far ...
    max_check_every: int = 3  # ... at least every this many steps
    budget: float = 4.0  # s of simulated time
    snap_after: float = 2.0  # s: after this, seams that stopped closing ...
    snap_stall: float = 0.5  # ... (the widest gap shrank < 1 mm over this long) ...
    snap_gap: float = 0.02  # m: ... within this are welded where they are; wider, sewing gives up (as soon as judged) ...
    snap_lone_gap: float = 0.03  # m: ... or within this, where every open pair is alone on its stitch
    # (its neighbours sewn: the last pair of a seam at a junction of panels, eased in as a sewist would)
    seam_flexion: bool = True  # bending springs across the sewn seams
    meet_outside: bool = True  # a flat layout's pair whose path runs through the body meets beside it (pull_seams)
    meet_margin: float = 0.01  # m: ... this far outside the body's surface nearest its midpoint

    def validate(self) -> None:
        if not (0.0 < self.check_travel <= 0.05):
            raise InputError(f"sew check_travel {self.check_travel} m: use a distance in (0, 0.05]")


@dataclass(frozen=True)
class DrapeTuning:
    """Draping: the sewn cloth settles under gravity until its shape stops moving."""

    relax: str = "fire"  # fire (engine.cloth.solver.FireRelaxer) or viscous (the seeds' damping alone)
    fire_damping: float = 100.0  # x the viscous damping while draping with FIRE ...
    damping: float = 1000.0  # ... or with viscous damping alone
    fire_ramp: float = 0.05  # s: with FIRE, gravity goes from where sewing left it to g over at most this
    check_time: float = 0.0004  # s: collisions are checked every floor(this / dt) steps ...
    max_check_every: int = 2  # ... at least every this many steps
    tight_every_step: float = 0.01  # past the fabric's threshold + this, collisions are checked every step ...
    tight_grace: float = 0.025  # s: ... after this much draping (the strain sewing leaves is worked off first)
    # a drape that settles stretched past the fabric's threshold + this while checking collisions every
    # other step goes on, checking every step, until it settles again (None: never): the strain guard
    # holds threshold + its guard, and where it could not the body pushed back between checks
    polish_at: float | None = 0.0075
    # ... and one that stays past it this long (s) before it settles is polished then (None: only once
    # settled): a GarmentCode top held 6.3-6.7 % in cotton for its whole 6 s budget, never settling,
    # fit cotton at 5.9 % within 0.15 s of being polished
    polish_tight_after: float | None = 0.3
    budget: float = 6.0  # s of simulated time
    # a drape whose cloth ends deeper in the body than this (m, against its mesh) settles again
    # against the mesh itself, for at most finish_budget s (engine.scene.drape._finish_exact; None: never)
    finish_pen: float | None = 0.0015
    finish_budget: float = 1.0
    min_time: float = 0.1  # s: drape at least this long
    settle_time: float = 0.05  # s: settled when the RMS drift over each of two windows this long ...
    settle_speed: float = 0.005  # m/s: ... is below this
    too_tight: float = 0.10  # strain past the fabric's threshold by this: refused as too small ...
    refuse_after: float = 2.0  # s: ... once it stayed so this long
    # a drape that another fabric will be tried after (engine.scene.tryon.run_tryon's knit) stops as
    # soon as it stayed stretched past the fabric's threshold + knit_give_up for knit_give_up_after s:
    # one that fits comes under it within a tenth of a second; one that does not ran to the budget
    give_up: bool = False
    knit_give_up: float = 0.05
    knit_give_up_after: float = 0.25
    # ... and, less stretched, as soon as it stayed past the threshold + tight_every_step (tight, as
    # the report says: the next fabric is tried anyway) for knit_tight_after s: such a drape ran to
    # its budget, the strain guard and the body fighting, before it was found tight (35-45 s of
    # wall time on a GarmentCode top that then fit jersey in 2 s)
    knit_tight_after: float = 0.6  # (drapes that fit were tight for 0.37 s at most: docs/tuning.md)
    # where FIRE settles with more than this share of the cloth standing out from the body unheld
    # (engine.scene.drape.standing_out: stand_out_far from it, within 45 degrees of level), the
    # cloth away from the body is let fall with viscous damping until under half as much is left
    # tilted past stand_out_hung (checked each settle window), for at most stand_out_for s, then
    # settles with FIRE again (None: never): a circle skirt's flat fan, not a skirt that hangs
    # (the figures: docs/tuning.md, stand_out)
    stand_out: float | None = 0.03
    stand_out_far: float = 0.10  # m
    stand_out_level: float = 0.7  # |normal y|: within 45 degrees of level
    stand_out_hung: float = 0.5  # ... and to have come down: within 60 degrees
    stand_out_for: float = 1.5  # s
    step: StepConfig = StepConfig(strain_guard=0.005)  # (sewing uses it too; its guard waits until welded)
    # a fabric allowed soft_from or more (a knit) is held soft_guard past its threshold: the softer
    # cloth overshoots the guard more between its passes (jersey ended 15.5-16.2 % at 0.5 %: either
    # side of the threshold + 1 % bar by chance)
    soft_from: float = 0.10
    soft_guard: float | None = 0.003
    # cloth-cloth contact within the garment while sewing and draping (engine.cloth.selfcontact):
    # auto = where parts may come to lie on each other (engine.scene.layers), on, or off
    self_contact: str = "auto"
    layer_gap: float = 0.03  # m: (auto) a vertex placed this near another panel ...
    layer_clear: float = 0.05  # m: ... and farther than this along its panel from any seam ...
    layer_share: float = 0.01  # ... on this share of the cloth: panels placed on each other

    def validate(self) -> None:
        if self.relax not in ("fire", "viscous"):
            raise InputError(f"unknown relaxation '{self.relax}': use fire or viscous")
        if self.self_contact not in ("auto", "on", "off"):
            raise InputError(f"self_contact '{self.self_contact}': use auto, on or off")
        if self.stand_out is not None and not (0.0 < self.stand_out <= 1.0):
            raise InputError(f"stand_out {self.stand_out}: use a share of the cloth in (0, 1] or None")
        for name, hi in (("layer_gap", 0.2), ("layer_clear", 1.0), ("layer_share", 1.0), ("stand_out_far", 1.0),
                         ("stand_out_level", 1.0), ("stand_out_hung", 1.0), ("stand_out_for", 10.0)):
            v = getattr(self, name)
            if not (0.0 < v <= hi):
                raise InputError(f"drape {name} {v}: use a positive number up to {hi:g}")
        if self.polish_at is not None and not (0.0 <= self.polish_at <= 1.0):
            raise InputError(f"polish_at {self.polish_at}: use 0 .. 1 (strain past the fabric's threshold) or None")
        if self.finish_pen is not None and not (0.0 < self.finish_pen <= 0.05):
            raise InputError(f"finish_pen {self.finish_pen} m: use a depth in (0, 0.05] or None")
        if not (0.0 < self.finish_budget <= 10.0):
            raise InputError(f"finish_budget {self.finish_budget} s: use a time in (0, 10]")
        if not (0.0 <= self.tight_every_step <= 1.0):
            raise InputError(f"tight_every_step {self.tight_every_step}: use 0 .. 1 (strain past the fabric's "
                             "threshold)")
        if not (-1.0 < self.knit_give_up <= 1.0 and 0.0 < self.knit_give_up_after <= 60.0):
            raise InputError(f"knit_give_up {self.knit_give_up} / knit_give_up_after {self.knit_give_up_after} s: "
                             "use a strain past the fabric's threshold in (-1, 1] and a time in (0, 60] s")
        if not (0.0 < self.knit_tight_after <= 60.0):
            raise InputError(f"knit_tight_after {self.knit_tight_after} s: use a time in (0, 60]")
        if self.polish_tight_after is not None and not (0.0 < self.polish_tight_after <= 60.0):
            raise InputError(f"polish_tight_after {self.polish_tight_after} s: use a time in (0, 60] or None")
        if not (0.0 < self.check_time <= 0.01):
            raise InputError(f"drape check_time {self.check_time} s: use a time in (0, 0.01]")


@dataclass(frozen=True)
class WalkTuning:
    """Walking: the dressed body walks, the cloth follows."""

    stiffen_at: float | None = 0.10  # a frame past the fabric's threshold + this doubles the springs (None: never)
    # ... over at least this many springs (or three times as far past it at one): one spring at a seam's
    # end is no reason to stiffen every spring for the rest of the walk (a shorter eq. 4 step)
    stiffen_springs: int = 8
    damping_cap: float = 0.5  # a spring's damping is at most this x m / (dt degree)
    check_travel: float = 0.00175  # m: collisions are checked as often as the body's bulk travels this far ...
    max_check_every: int = 8  # ... at least every this many steps
    friction: float = 1.0  # x the fabric's cloth-body friction
    # m: the walk's collision band, wider than the drape's: cloth carried by a swinging leg travels
    # further between two checks than resting cloth, and a 3 mm band let it dip 8-12 mm (docs/tuning.md)
    tolerance: float = 0.005
    render_ahead: bool = True  # maps rendered one frame ahead in a helper thread
    prerender: bool = True  # a periodic walk's maps all rendered before the walking stage
    step: StepConfig = StepConfig(strain_guard=0.02, flexion_every=8, push_time=0.005, precision="single",
                                  hold_shear=True, keep_forces=False, late_guard=True)

    def validate(self) -> None:
        if self.stiffen_at is not None and not (0.0 < self.stiffen_at <= 0.4):
            raise InputError(f"stiffen_at {self.stiffen_at}: use 0 .. 0.4 (strain past the fabric's threshold), "
                             "or None")
        if not (1 <= self.stiffen_springs <= 10_000):
            raise InputError(f"stiffen_springs {self.stiffen_springs}: use 1 .. 10000 springs")
        if not (0.0 < self.damping_cap <= 1.0):
            raise InputError(f"damping_cap {self.damping_cap}: use 0 .. 1 (x m / (dt degree))")
        if not (0.0 <= self.friction <= 2.0):
            raise InputError(f"friction scale {self.friction}: use 0 .. 2")
        if not (0.0005 <= self.tolerance <= 0.02):
            raise InputError(f"walk tolerance {self.tolerance} m: use 0.0005 .. 0.02 (0.5 mm .. 2 cm)")


@dataclass(frozen=True)
class Tuning:
    """Every stage's tuning, and what they share."""

    cloth: ClothParams = ClothParams()
    sew: SewTuning = SewTuning()
    drape: DrapeTuning = DrapeTuning()
    walk: WalkTuning = WalkTuning()
    collide_every: int | None = None  # steps between collision checks in every stage (None: each stage's rule)
    observe_every: float = 0.02  # s of simulated time between the cloth's updates to a live view

    def validate(self) -> None:
        k = self.collide_every
        if k is not None and not (isinstance(k, int) and 1 <= k <= 16):
            raise InputError(f"collide_every {k}: check collisions every 1 .. 16 steps")
        self.sew.validate()
        self.drape.validate()
        self.walk.validate()

