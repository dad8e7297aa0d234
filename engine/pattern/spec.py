"""Sewing patterns in GarmentCode's JSON "specification" format, read with pydantic.

A spec holds `pattern.panels` (2D outline vertices, edges with optional curvature, a 3D
translation and rotation that place the flat panel around the body), `pattern.stitches` (pairs
of {panel, edge} sewn together, with GarmentCode's optional sewing side) and `properties` (`units_in_meter`, `curvature_coords`).
GarmentCode fields we do not use (`parameters`, `parameter_order`, ...) are kept so a pattern
written back out is still a GarmentCode spec. Our own additions (fabric, placement hints) live
in an optional top-level `tryon` block that GarmentCode ignores.

Conventions taken from GarmentCode (pygarment):
- edge curvature `quadratic` / `cubic`: control points in coordinates relative to the edge
  (x along start->end as a fraction, y along the edge rotated +90 degrees, same scale);
- `circle`: params = [radius (absolute, pattern units), large_arc (0/1), right (0/1)]; `right`
  = the arc bulges to the right of the start->end direction;
- panel rotation: Euler angles in degrees, intrinsic XYZ; translation in pattern units.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_serializer, model_validator


class Curvature(BaseModel):
    model_config = ConfigDict(extra="allow")
    type: Literal["quadratic", "cubic", "circle"]
    params: list[Any]

    @model_validator(mode="after")
    def _check_params(self) -> "Curvature":
        n = {"quadratic": 1, "cubic": 2}.get(self.type)
        if n is not None:
            if len(self.params) != n or not all(_is_point(p) for p in self.params):
                raise ValueError(f"{self.type} curvature needs {n} control point(s) [x, y], got {self.params!r}")
        else:
            if len(self.params) != 3 or not all(isinstance(p, (int, float)) for p in self.params):
                raise ValueError(f"circle curvature needs [radius, large_arc, right], got {self.params!r}")
            if not self.params[0] > 0:
                raise ValueError(f"circle radius must be positive, got {self.params[0]!r}")
        return self


def _is_point(p: Any) -> bool:
    return isinstance(p, (list, tuple)) and len(p) == 2 and all(isinstance(c, (int, float)) for c in p)


class Edge(BaseModel):
    model_config = ConfigDict(extra="allow")
    endpoints: tuple[int, int]
    curvature: Curvature | None = None
    label: str | None = None


class Panel(BaseModel):
    model_config = ConfigDict(extra="allow")
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    vertices: list[tuple[float, float]]
    edges: list[Edge]
    label: str | None = None

    @field_validator("vertices")
    @classmethod
    def _enough_vertices(cls, v: list) -> list:
        if len(v) < 2:
            raise ValueError(f"a panel needs at least 2 vertices, got {len(v)}")
        return v

    @model_validator(mode="after")
    def _edges_in_range(self) -> "Panel":
        n = len(self.vertices)
        for i, e in enumerate(self.edges):
            for k in e.endpoints:
                if not 0 <= k < n:
                    raise ValueError(f"edge {i} names vertex {k}, but the panel has vertices 0..{n - 1}")
        return self


class StitchSide(BaseModel):
    model_config = ConfigDict(extra="allow")
    panel: str
    edge: int


class Stitch(BaseModel):
    """Two edges sewn together, written [a, b] or [a, b, side] as GarmentCode writes them. `side`:
    GarmentCode's sewing orientation -- "right_wrong": one panel's right side to the other's wrong
    side (its collars), where a plain stitch joins right side to right side; kept as written."""

    model_config = ConfigDict(extra="forbid")
    a: StitchSide
    b: StitchSide
    side: str | None = None

    @model_validator(mode="before")
    @classmethod
    def _from_list(cls, v: Any) -> Any:
        if isinstance(v, (list, tuple)):
            if len(v) not in (2, 3):
                raise ValueError(f"a stitch is [edge, edge] or [edge, edge, side], got {len(v)} items")
            if len(v) == 3 and not isinstance(v[2], str):
                raise ValueError(f"a stitch's third item is its sewing side (a name), got {v[2]!r}")
            return {"a": v[0], "b": v[1], "side": v[2] if len(v) == 3 else None}
        return v

    @model_serializer
    def _as_list(self) -> list:
        pair = [self.a.model_dump(), self.b.model_dump()]
        return pair + [self.side] if self.side is not None else pair

    def __iter__(self):  # (a, b = stitch)
        return iter((self.a, self.b))


class PatternBody(BaseModel):
    model_config = ConfigDict(extra="allow")
    panels: dict[str, Panel]
    stitches: list[Stitch] = Field(default_factory=list)
    panel_order: list[str] | None = None

    @field_validator("panels")
    @classmethod
    def _some_panels(cls, v: dict) -> dict:
        if not v:
            raise ValueError("the pattern has no panels")
        return v


class Properties(BaseModel):
    model_config = ConfigDict(extra="allow")
    units_in_meter: float = 100.0
    curvature_coords: Literal["relative", "absolute"] = "relative"

    @field_validator("units_in_meter")
    @classmethod
    def _positive(cls, v: float) -> float:
        if not v > 0:
            raise ValueError(f"units_in_meter must be positive, got {v}")
        return v


class PanelHint(BaseModel):
    """Our placement hint for one panel: which body region it wraps and on which side."""

    model_config = ConfigDict(extra="forbid")
    region: Literal["torso", "left_arm", "right_arm", "left_leg", "right_leg", "hips"] = "torso"
    side: Literal["front", "back", "left", "right", "around"] = "front"
    # a panel inferred from a DXF pattern (engine.pattern.dxf_infer: its frame; placed by
    # engine.garment.dxf_place): a front or back, a sleeve, a leg, or a band round the loop of
    # edges it is sewn to (collar, cuff, waistband)
    role: Literal["bodice", "sleeve", "leg", "band"] | None = None
    # its key points (name -> [u, v] in pattern units, the panel's frame) that the placement uses:
    # a bodice's shoulder and underarm points, a sleeve's cap ends, a leg's waist and crotch points
    points: dict[str, tuple[float, float]] = Field(default_factory=dict)


class TryonExtension(BaseModel):
    """The optional `tryon` block (ignored by GarmentCode)."""

    model_config = ConfigDict(extra="forbid")
    fabric: str | None = None
    fabric_why: str | None = None  # why the pattern has this fabric (a DXF's suggestion: engine.pattern.dxf_fabric)
    placement: dict[str, PanelHint] = Field(default_factory=dict)
    made_for_body: str | None = None  # a body name/file the spec's own placement fits
    # how stitched edges pair up: GarmentCode's rule (None: head to tail, "right_wrong" stitches
    # the same way), or "placed": the way round whose ends lie closer as placed (the DXF importer's
    # stitches, whose edges' directions follow the cut pieces, some of them mirrored)
    pairing: Literal["placed"] | None = None


class PatternSpec(BaseModel):
    """A whole GarmentCode specification file (+ our optional extension)."""

    model_config = ConfigDict(extra="allow")
    pattern: PatternBody
    properties: Properties = Field(default_factory=Properties)
    tryon: TryonExtension | None = None

    @property
    def scale(self) -> float:
        """Metres per pattern unit."""
        return 1.0 / self.properties.units_in_meter
