"""Bodies: load and normalise scans, the default parametric body, measurements.

`resolve_body(spec)` is the one entry point the CLI and the service use:
  "default:female" / "default:male"             the parametric default body (a preset)
  "default:female,height=1.75,weight=0.7"     a preset with shape parameters
  "path/to/scan.obj" (.ply .stl .off .glb .gltf) a mesh file, normalised
"""

from __future__ import annotations

from pathlib import Path

from engine.body.types import SEGMENT_ID, SEGMENTS, Body, Rig
from engine.errors import InputError

__all__ = ["Body", "Rig", "SEGMENTS", "SEGMENT_ID", "resolve_body", "parse_default_spec"]


def parse_default_spec(spec: str) -> tuple[str, dict[str, float]]:
    """'default:female,height=1.7' -> ('female', {'height': 1.7})."""
    rest = spec.split(":", 1)[1] if ":" in spec else ""
    parts = [p.strip() for p in rest.split(",") if p.strip()]
    if not parts:
        raise InputError(f"body '{spec}': name a preset, e.g. default:female or default:male")
    preset, params = parts[0], {}
    for p in parts[1:]:
        if "=" not in p:
            raise InputError(f"body '{spec}': shape parameter '{p}' must look like name=value")
        k, v = p.split("=", 1)
        try:
            params[k.strip()] = float(v)
        except ValueError:
            raise InputError(f"body '{spec}': value of '{k.strip()}' is not a number: '{v}'") from None
    return preset, params


def resolve_body(spec: str, *, up: str | None = None, front: str | None = None,
                 max_triangles: int | None = None) -> Body:
    """Turn a body spec (see module doc) into a normalised Body."""
    if spec.startswith("default:") or spec == "default":
        from engine.body.default import default_body

        preset, params = parse_default_spec(spec)
        return default_body(preset, **params)
    path = Path(spec)
    if not path.exists():
        raise InputError(f"body file not found: {spec} (give a mesh file or default:female / default:male)")
    from engine.body.load import load_body_file

    kwargs = {} if max_triangles is None else {"max_triangles": max_triangles}
    return load_body_file(path, up=up, front=front, **kwargs)
