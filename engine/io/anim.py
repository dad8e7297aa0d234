"""Animated GLB: meshes whose vertices move, as glTF 2.0 morph targets played by an animation.

    write_anim_glb(path, [("body", body_faces, body_frames, BODY_RGBA),
                          ("garment", garment_faces, garment_frames, GARMENT_RGBA)], fps=30)

Each mesh's first frame is its base geometry; every later frame is a morph target holding its
displacement from the base, and the animation's weights sampler (LINEAR) moves the weight from
one target to the next, so any glTF viewer plays the motion with in-between frames blended.
No normals are written: viewers then shade with normals from the moving geometry (three.js
and Blender compute them; stale rest-pose normals would light a swinging arm wrongly).
glTF's frame is ours (Y up, metres), so nothing is converted.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from engine.errors import InputError

_FLOAT, _UINT = 5126, 5125
_ARRAY, _ELEMENTS = 34962, 34963


class _Builder:
    def __init__(self):
        self.chunks: list[bytes] = []
        self.offset = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, data: np.ndarray, component: int, kind: str, target: int | None = None,
            minmax: bool = False) -> int:
        raw = np.ascontiguousarray(data).tobytes()
        pad = (-len(raw)) % 4
        view = {"buffer": 0, "byteOffset": self.offset, "byteLength": len(raw)}
        if target is not None:
            view["target"] = target
        self.views.append(view)
        self.chunks.append(raw + b"\0" * pad)
        self.offset += len(raw) + pad
        acc = {"bufferView": len(self.views) - 1, "componentType": component,
               "count": int(data.shape[0]), "type": kind}
        if minmax:
            flat = data.reshape(data.shape[0], -1)
            acc["min"] = [float(x) for x in flat.min(axis=0)]
            acc["max"] = [float(x) for x in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def write_anim_glb(path: str | Path, meshes: list[tuple[str, np.ndarray, np.ndarray, tuple]], fps: float) -> Path:
    """meshes: (name, faces (F, 3) int, frames (T, N, 3) float, rgba 0..255); every mesh has the
    same number of frames T >= 1. Returns the path written."""
    if not meshes:
        raise InputError("nothing to write: no meshes")
    n_frames = {int(np.asarray(fr).shape[0]) for _, _, fr, _ in meshes}
    if len(n_frames) != 1:
        raise InputError(f"all meshes need the same number of frames, got {sorted(n_frames)}")
    t = n_frames.pop()
    if t < 1 or not fps > 0:
        raise InputError("an animation needs at least one frame and fps > 0")
    b = _Builder()
    gl_meshes, nodes, materials = [], [], []
    times = (np.arange(t, dtype=np.float32) / np.float32(fps))
    anim_samplers, anim_channels = [], []
    for mi, (name, faces, frames, rgba) in enumerate(meshes):
        frames = np.asarray(frames, np.float32)
        if not np.all(np.isfinite(frames)):
            raise InputError(f"mesh '{name}' has non-finite vertex positions; refusing to write them")
        faces = np.asarray(faces, np.uint32)
        base = frames[0]
        prim = {"attributes": {"POSITION": b.add(base, _FLOAT, "VEC3", _ARRAY, minmax=True)},
                "indices": b.add(faces.reshape(-1), _UINT, "SCALAR", _ELEMENTS), "material": mi}
        targets = [{"POSITION": b.add(frames[k] - base, _FLOAT, "VEC3", _ARRAY, minmax=True)} for k in range(1, t)]
        if targets:
            prim["targets"] = targets
        materials.append({"name": name, "doubleSided": name != "body",
                          "pbrMetallicRoughness": {"baseColorFactor": [c / 255.0 for c in rgba],
                                                   "metallicFactor": 0.0, "roughnessFactor": 0.9}})
        mesh = {"name": name, "primitives": [prim]}
        if targets:
            mesh["weights"] = [0.0] * len(targets)
        gl_meshes.append(mesh)
        nodes.append({"name": name, "mesh": mi})
        if targets:
            w = np.zeros((t, t - 1), np.float32)  # frame k shows target k-1 at weight 1
            w[np.arange(1, t), np.arange(t - 1)] = 1.0
            inp = b.add(times, _FLOAT, "SCALAR", minmax=True)
            out = b.add(w.reshape(-1), _FLOAT, "SCALAR")
            anim_samplers.append({"input": inp, "output": out, "interpolation": "LINEAR"})
            anim_channels.append({"sampler": len(anim_samplers) - 1, "target": {"node": mi, "path": "weights"}})
    doc = {"asset": {"version": "2.0", "generator": "tryon"}, "scene": 0,
           "scenes": [{"nodes": list(range(len(nodes)))}], "nodes": nodes, "meshes": gl_meshes,
           "materials": materials, "accessors": b.accessors, "bufferViews": b.views,
           "buffers": [{"byteLength": b.offset}]}
    if anim_channels:
        doc["animations"] = [{"name": "walk", "samplers": anim_samplers, "channels": anim_channels}]
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    binary = b"".join(b.chunks)
    total = 12 + 8 + len(js) + 8 + len(binary)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".glb.part")
    with open(tmp, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, total))
        f.write(struct.pack("<I4s", len(js), b"JSON"))
        f.write(js)
        f.write(struct.pack("<I4s", len(binary), b"BIN\0"))
        f.write(binary)
    tmp.replace(path)
    return path
