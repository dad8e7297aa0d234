"""What a user sets for a try-on: one model for the command line (`tryon drape`, `tryon walk`) and
the service (`POST /api/tryons`). The engine's tuning is apart from it (engine.scene.tuning)."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from engine.cloth.fabrics import get_fabric
from engine.errors import InputError


class TryOnOptions(BaseModel):
    """How to simulate: fabric, cloth and map resolution, method, and the walk."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    fabric: str | None = Field(None, description="cotton, denim, silk, jersey, stretch_knit (elastane jersey: "
                               "leggings) or rib_knit (cuffs and bands); default: the pattern's own -- a DXF of a "
                               "stretch knit garment suggests stretch_knit -- else cotton (a pattern file whose cuffs "
                               "or bands are cut smaller round than the body is draped again with those parts in "
                               "stretch_knit, and where still too small, in rib_knit; one too "
                               "tight in cotton as a whole, cut with no ease, in jersey, and if too tight in "
                               "jersey too, in stretch_knit)")
    resolution_cm: float = Field(1.5, ge=0.2, le=20.0, description="cloth edge length, cm")
    texel_mm: float = Field(5.0, ge=0.5, le=50.0, description="collision map texel, mm (seed 003 §5.4: 5 mm)")
    collision: Literal["image", "object"] = Field("image", description="image (depth/normal maps) or object (BVH)")
    velocity_mode: Literal["zero", "average", "directional", "provot"] = Field(
        "average", description="super-elasticity rule: zero (seed 003), average (eq. 5), directional (eq. 6; "
        "not yet stable while walking) or provot (position modification)")
    dt_ms: float | None = Field(None, description="time step, ms (default: the eq. 4 bound; above it only with "
                                "force_dt)")
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

    @field_validator("dt_ms")
    @classmethod
    def _positive_dt(cls, v):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"time step must be positive, got {v} ms")
        return v

    @field_validator("fabric")
    @classmethod
    def _known_fabric(cls, v):
        if v is None:
            return v
        try:
            get_fabric(v)
        except InputError as e:  # (it names the fabrics)
            raise ValueError(str(e)) from None
        return v

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
    def walk(self):
        """The procedural walk's parameters (engine.body.motion.WalkParams)."""
        from engine.body.motion import WalkParams

        return WalkParams(speed=self.speed, stride=self.stride, in_place=self.in_place)

    @classmethod
    def of(cls, names: dict[str, str] | None = None, **values):
        """The model of `values`, or InputError naming what is wrong in plain words (a field by
        its name in `names`, e.g. the command line's option, where given)."""
        try:
            return cls(**values)
        except ValidationError as e:
            raise InputError("; ".join(plain_error(cls, err, names or {}) for err in e.errors())) from None


def plain_error(model: type[BaseModel], err: dict, names: dict[str, str]) -> str:
    """One pydantic error as a user reads it: the field, the value given, what is wrong."""
    field = ".".join(str(x) for x in err["loc"]) or "request"
    name = names.get(field, field)
    given = err.get("input")
    if err["type"] in ("greater_than_equal", "less_than_equal", "greater_than", "less_than"):
        f = model.model_fields.get(str(err["loc"][0])) if err["loc"] else None
        lo = next((m.ge if m.ge is not None else m.gt for m in (f.metadata if f else [])
                   if getattr(m, "ge", None) is not None or getattr(m, "gt", None) is not None), None)
        hi = next((m.le if m.le is not None else m.lt for m in (f.metadata if f else [])
                   if getattr(m, "le", None) is not None or getattr(m, "lt", None) is not None), None)
        return f"{name} {given}: out of range ({lo:g} .. {hi:g})" if None not in (lo, hi) else \
            f"{name} {given}: {err['msg']}"
    msg = str(err["msg"]).removeprefix("Value error, ")
    return f"{name} {given!r}: {msg}" if err["type"] != "missing" else f"{name}: missing"


class TryOnRequest(TryOnOptions):
    """A try-on: the garment (a catalogue name, or a pattern) and its size, and how to simulate."""

    garment: str = Field(..., description="a catalogue garment (see `tryon garments`) or a pattern: a "
                         "GarmentCode JSON file, or a DXF cutting pattern (.dxf: its seams and placement "
                         "inferred, see `tryon pattern import`) (the service: the id of an uploaded pattern)")
    size: str | None = Field(None, description="catalogue size XS, S, M, L, XL, XXL (default M), on the women's or "
                             "men's chart (a default body's own, any other body's by the sex its shape reads); a "
                             "DXF pattern's own size names (default: its sample size); or auto: the smallest size "
                             "whose girths cover the body's (catalogue: the chart's; DXF: the pieces' chest or hip "
                             "width, with ease), then by draping: the next larger while it comes out too small "
                             "(refused, or tight), up to two more, the next smaller while it slides down the body; "
                             "when none fits, the report says so. Not for GarmentCode patterns")
    assembly: str | None = Field(None, description="with a DXF pattern: an assembly file (JSON) to use instead of "
                                 "the inferred seams -- the assembly.json `tryon pattern import` writes, corrected "
                                 "(it serves every size), or GarmentCode's kind (the service: upload it with the DXF)")
    units: str | None = Field(None, description="with a DXF that does not say its units: mm, cm, m or in (the "
                              "service: upload them with the DXF)")
