"""What a user sets for a try-on: one model for the command line (`tryon drape`, `tryon walk`) and
the service (`POST /api/tryons`). The engine's tuning is apart from it (engine.scene.tuning)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from engine.body.motion import WalkParams
from engine.errors import InputError


class TryOnOptions(BaseModel):
    """How to simulate: fabric, cloth and map resolution, method, and the walk."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    fabric: str = Field("cotton", description="cotton, denim, silk or jersey")
    resolution_cm: float = Field(1.5, ge=0.5, le=6.0, description="cloth edge length, cm")
    texel_mm: float = Field(5.0, ge=0.5, le=50.0, description="collision map texel, mm (seed 003 §5.4: 5 mm)")
    collision: Literal["image", "object"] = Field("image", description="image (depth/normal maps) or object (BVH)")
    velocity_mode: Literal["zero", "average", "directional", "provot"] = Field(
        "average", description="super-elasticity rule: zero (seed 003), average (eq. 5), directional (eq. 6; "
        "not yet stable while walking) or provot (position modification)")
    dt_ms: float | None = Field(None, gt=0.0, le=10.0, description="time step, ms (default: the eq. 4 bound)")
    force_dt: bool = Field(False, description="allow a time step above the eq. 4 bound")
    motion: Literal["none", "walk"] = Field("none", description="stand, or walk after dressing")
    seconds: float = Field(4.0, ge=0.1, le=60.0, description="walking time, s (motion=walk)")
    fps: float = Field(30.0, ge=5.0, le=120.0, description="body and output frames per second while walking")
    speed: float = Field(1.2, ge=0.1, le=5.0, description="walking speed, m/s (1.2: a normal walk)")
    stride: float | None = Field(None, ge=0.3, le=2.5, description="stride (two steps), m; default 0.82 x height")
    in_place: bool = Field(False, description="walk on the spot (a treadmill)")
    walk_stiffness: float = Field(0.25, ge=0.01, le=1.0, description="stretch and shear springs while walking, "
                                  "x the drape's: softer springs take a longer eq. 4 step")
    reuse_maps: bool = Field(True, description="a periodic walk renders one cycle of collision maps and reuses it")

    @property
    def h(self) -> float:
        """The cloth edge, m."""
        return self.resolution_cm / 100.0

    @property
    def texel(self) -> float:
        """The map texel, m."""
        return self.texel_mm / 1000.0

    @property
    def dt(self) -> float | None:
        """The time step, s (None: the eq. 4 bound)."""
        return None if self.dt_ms is None else self.dt_ms / 1000.0

    @property
    def walk(self) -> WalkParams:
        return WalkParams(speed=self.speed, stride=self.stride, in_place=self.in_place)

    @classmethod
    def of(cls, **values):
        """The model of `values`, or InputError naming what is wrong in plain words."""
        try:
            return cls(**values)
        except ValidationError as e:
            raise InputError("; ".join(f"{'.'.join(str(x) for x in err['loc'])}: {err['msg']}"
                                       for err in e.errors())) from None


class TryOnRequest(TryOnOptions):
    """A try-on: the garment (a catalogue name, or a pattern) and its size, and how to simulate."""

    garment: str = Field(..., description="a catalogue name, or a pattern")
    size: str | None = Field(None, description="catalogue size XS..XXL, or auto: the smallest that covers the "
                             "body's girths and drapes without being too small (default M); not for patterns")
