"""An animated glTF 2.0 body (.glb, or .gltf with embedded data): its mesh sampled at a frame rate.

    frames, faces, notes = sample_gltf_animation("walk.glb", fps=30)   # (T, N, 3), (F, 3)

What is read (glTF 2.0 spec, sections "Animations", "Skins", "Morph Targets"):
- every triangle primitive of every mesh node in the default scene, merged into one mesh, with
  its node's world transform (a skinned mesh takes its joints' transforms instead, as the spec says);
- morph targets (POSITION displacements, sparse accessors included) weighted by the node's
  animated `weights`, else the node's or the mesh's default weights;
- skins: JOINTS_n / WEIGHTS_n (any number of sets), inverse bind matrices, the joints' node
  hierarchy with animated translation / rotation / scale (or a fixed matrix);
- the first animation, with STEP, LINEAR (quaternions: slerp) and CUBICSPLINE samplers, sampled
  at k / fps from 0 to its last key.
Not read: other animations in the file (a note says so), points and lines, external buffer
files (an upload is one file), KHR extensions that change geometry (Draco compression).
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

from engine.errors import MALFORMED, InputError, parser

_COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_NORM = {np.int8: 127.0, np.uint8: 255.0, np.int16: 32767.0, np.uint16: 65535.0}
MAX_SECONDS = 120.0
MAX_FRAMES = 3000  # frames sampled at most (engine.body.animation refuses more too)
MAX_VALUES = 50_000_000  # accessor values (count x width) and sampled coordinates at most: ~400 MB in float64
MAX_PARTS = 512  # triangle primitives in the scene: a body is one or a few meshes (3,000 copies of one
                 # 20-vertex primitive, a 240 KB file, took 30 s to merge)


class _File:
    def __init__(self, path: Path, buffers: bool = True):
        """buffers=False: the JSON only (enough to see whether the file is animated)."""
        self.name = path.name
        raw = path.read_bytes()
        if raw[:4] == b"glTF":
            self.doc, self.bin = self._glb(raw)
        else:
            try:
                self.doc = json.loads(raw.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError):
                raise InputError(f"{self.name} is neither a binary glTF (.glb) nor glTF JSON") from None
            self.bin = None
        if not isinstance(self.doc, dict) or not str(self.doc.get("asset", {}).get("version", "")).startswith("2"):
            raise InputError(f"{self.name}: only glTF 2.0 files are read")
        self.buffers = [self._buffer(i, b) for i, b in enumerate(self.doc.get("buffers", []))] if buffers else []
        self._acc_cache: dict[int, np.ndarray] = {}

    def _glb(self, raw: bytes):
        if len(raw) < 20:
            raise InputError(f"{self.name}: the GLB file is truncated")
        _, version, length = struct.unpack_from("<4sII", raw, 0)
        if version != 2:
            raise InputError(f"{self.name}: GLB version {version}; only glTF 2.0 is read")
        pos, doc, binary = 12, None, None
        while pos + 8 <= min(length, len(raw)):
            size, kind = struct.unpack_from("<II", raw, pos)
            chunk = raw[pos + 8:pos + 8 + size]
            if len(chunk) != size:
                raise InputError(f"{self.name}: the GLB file is truncated")
            if kind == 0x4E4F534A:
                try:
                    doc = json.loads(chunk.decode("utf-8"))
                except (UnicodeDecodeError, json.JSONDecodeError):
                    raise InputError(f"{self.name}: the GLB's JSON chunk is not valid JSON") from None
            elif kind == 0x004E4942 and binary is None:
                binary = chunk
            pos += 8 + size + ((-size) % 4)
        if doc is None:
            raise InputError(f"{self.name}: the GLB has no JSON chunk")
        return doc, binary

    def _buffer(self, i: int, b: dict) -> bytes:
        uri = b.get("uri")
        if uri is None:
            if self.bin is None:
                raise InputError(f"{self.name}: buffer {i} has no data (no GLB binary chunk)")
            return self.bin
        if uri.startswith("data:") and ";base64," in uri:
            return base64.b64decode(uri.split(";base64,", 1)[1])
        raise InputError(f"{self.name}: buffer {i} refers to an external file '{uri}'; upload a .glb (one file "
                         "with its data inside)")

    def accessor(self, i: int) -> np.ndarray:
        """(count, width) float64 (or the integer values for index/joint accessors)."""
        if i in self._acc_cache:
            return self._acc_cache[i]
        try:
            a = self.doc["accessors"][i]
            dtype = _COMPONENT[a["componentType"]]
            width, count = _WIDTH[a["type"]], int(a["count"])
        except (IndexError, KeyError, TypeError):
            raise InputError(f"{self.name}: accessor {i} is missing or malformed") from None
        if not 0 <= count * width <= MAX_VALUES:  # checked before anything is allocated
            raise InputError(f"{self.name}: accessor {i} claims {count:,} elements: the file is corrupt or too large")
        item = np.dtype(dtype).itemsize
        if "bufferView" in a:
            view = self.doc["bufferViews"][a["bufferView"]]
            data = self.buffers[view["buffer"]]
            start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
            stride = view.get("byteStride") or item * width
            if stride < item * width:  # rows would overlap: one small buffer read as many elements
                raise InputError(f"{self.name}: accessor {i} has a byte stride of {stride}, less than its "
                                 f"element ({item * width} bytes): the file is corrupt")
            end = start + (count - 1) * stride + item * width if count else start
            if end > view.get("byteOffset", 0) + view["byteLength"] or end > len(data):
                raise InputError(f"{self.name}: accessor {i} reads past its buffer: the file is corrupt")
            rows = np.ndarray((count, width), dtype=dtype, buffer=data, offset=start, strides=(stride, item))
            out = np.array(rows)
        else:
            out = np.zeros((count, width), dtype=dtype)
        if "sparse" in a:
            sp = a["sparse"]
            n = int(sp["count"])
            if not 0 <= n <= count:
                raise InputError(f"{self.name}: accessor {i} has {n:,} sparse values for {count:,} elements")
            iv = self.doc["bufferViews"][sp["indices"]["bufferView"]]
            idx = np.frombuffer(self.buffers[iv["buffer"]], dtype=_COMPONENT[sp["indices"]["componentType"]], count=n,
                                offset=iv.get("byteOffset", 0) + sp["indices"].get("byteOffset", 0))
            vv = self.doc["bufferViews"][sp["values"]["bufferView"]]
            vals = np.frombuffer(self.buffers[vv["buffer"]], dtype=dtype, count=n * width,
                                 offset=vv.get("byteOffset", 0) + sp["values"].get("byteOffset", 0))
            if n and idx.max() >= count:
                raise InputError(f"{self.name}: accessor {i} has sparse indices past its count: the file is corrupt")
            out[idx.astype(np.int64)] = vals.reshape(n, width)
        if a.get("normalized") and dtype in _NORM:
            out = np.maximum(out.astype(np.float64) / _NORM[dtype], -1.0)
        elif dtype == np.float32:
            out = out.astype(np.float64)
        self._acc_cache[i] = out
        return out


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q / max(np.linalg.norm(q), 1e-12)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _slerp(a: np.ndarray, b: np.ndarray, u: float) -> np.ndarray:
    d = float(np.dot(a, b))
    if d < 0.0:
        b, d = -b, -d
    if d > 0.9995:
        q = a + u * (b - a)
    else:
        th = np.arccos(min(d, 1.0))
        q = (np.sin((1 - u) * th) * a + np.sin(u * th) * b) / np.sin(th)
    return q / max(np.linalg.norm(q), 1e-12)


class _Sampler:
    def __init__(self, f: _File, s: dict, path: str):
        self.t = f.accessor(s["input"])[:, 0]
        out = f.accessor(s["output"])
        self.interp = s.get("interpolation", "LINEAR")
        if self.interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
            raise InputError(f"{f.name}: unknown animation interpolation '{self.interp}'")
        n = len(self.t)
        if n == 0 or not np.all(np.isfinite(self.t)) or np.any(np.diff(self.t) < 0):
            raise InputError(f"{f.name}: an animation sampler's key times are empty or not increasing")
        per_key = len(out) // n // (3 if self.interp == "CUBICSPLINE" else 1)
        if per_key < 1:
            raise InputError(f"{f.name}: an animation sampler has fewer values than key times")
        # weights: one key holds every morph target's weight (a scalar accessor of n * targets)
        self.v = out.reshape(n, 3 if self.interp == "CUBICSPLINE" else 1, per_key * out.shape[1])
        self.rotation = path == "rotation"

    def at(self, t: float) -> np.ndarray:
        ts, v = self.t, self.v
        val = 1 if self.interp == "CUBICSPLINE" else 0
        if t <= ts[0] or len(ts) == 1:
            return v[0, val].copy()
        if t >= ts[-1]:
            return v[-1, val].copy()
        k = int(np.searchsorted(ts, t, side="right")) - 1
        d = ts[k + 1] - ts[k]
        u = (t - ts[k]) / d if d > 0 else 0.0
        if self.interp == "STEP":
            return v[k, 0].copy()
        if self.interp == "LINEAR":
            return _slerp(v[k, 0], v[k + 1, 0], u) if self.rotation else (1 - u) * v[k, 0] + u * v[k + 1, 0]
        u2, u3 = u * u, u * u * u  # cubic Hermite: (in-tangent, value, out-tangent) per key
        r = ((2 * u3 - 3 * u2 + 1) * v[k, 1] + (u3 - 2 * u2 + u) * d * v[k, 2]
             + (-2 * u3 + 3 * u2) * v[k + 1, 1] + (u3 - u2) * d * v[k + 1, 0])
        return r / max(np.linalg.norm(r), 1e-12) if self.rotation else r


def _node_parents(name: str, nodes: list) -> dict[int, int]:
    """{child: parent} of the node hierarchy, which glTF requires to be disjoint trees: a node
    with two parents, a child that does not exist or a cycle is refused (before anything walks it)."""
    parent: dict[int, int] = {}
    for i, n in enumerate(nodes):
        for c in n.get("children", []):
            c = int(c)
            if not 0 <= c < len(nodes) or c == i or c in parent:
                raise InputError(f"{name}: node {i} lists child {c}, which does not exist or already has a "
                                 "parent: the node hierarchy must be trees")
            parent[c] = i
    rooted: set[int] = set()  # nodes known to reach a root: each node is walked once
    for i in range(len(nodes)):
        walk, j = [], i
        while j not in rooted and j in parent:
            walk.append(j)
            j = parent[j]
            if j == i or len(walk) > len(nodes):
                raise InputError(f"{name}: the nodes' children form a cycle through node {i}: the node "
                                 "hierarchy must be trees")
        rooted.update(walk)
    return parent


def has_animation(path: str | Path) -> bool:
    """Whether a glTF file holds an animation (a static .glb is a scan, not a motion)."""
    path = Path(path)
    if path.suffix.lower() not in (".glb", ".gltf") or not path.is_file():
        return False
    try:
        return bool(_File(path, buffers=False).doc.get("animations"))
    except (InputError, *MALFORMED):  # not readable as animated glTF: the scan loader says why
        return False


@parser("an animated glTF")
def sample_gltf_animation(path: str | Path, fps: float) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(frames (T, N, 3) float64 in the file's axes and units, faces (F, 3) int64, notes)."""
    path = Path(path)
    f = _File(path)
    doc = f.doc
    anims = doc.get("animations") or []
    if not anims:
        raise InputError(f"{path.name} has no animation: give a glTF with morph-target or skinned animation, "
                         "or use it as a static scan")
    notes = []
    if len(anims) > 1:
        notes.append(f"animations 2..{len(anims)} of {path.name}, because a walk plays one (the first, "
                     f"'{anims[0].get('name', '0')}')")
    nodes = doc.get("nodes", [])
    channels = {}  # (node, path) -> sampler
    try:
        samplers = anims[0]["samplers"]
        for ch in anims[0]["channels"]:
            tgt = ch["target"]
            if "node" in tgt and tgt["path"] in ("translation", "rotation", "scale", "weights"):
                channels[(int(tgt["node"]), tgt["path"])] = _Sampler(f, samplers[ch["sampler"]], tgt["path"])
    except (KeyError, IndexError, TypeError):
        raise InputError(f"{path.name}: the animation's channels or samplers are malformed") from None
    if not channels:
        raise InputError(f"{path.name}: the animation moves nothing (no node channels)")
    end = max(s.t[-1] for s in channels.values())
    if end > MAX_SECONDS:
        raise InputError(f"{path.name}: the animation lasts {end:.0f} s, more than {MAX_SECONDS:.0f} s: shorten it")
    n_frames = int(np.floor(end * fps + 1e-6)) + 1
    if n_frames < 2:
        raise InputError(f"{path.name}: the animation lasts {end:.3f} s, under one frame at {fps:g} fps")
    if n_frames > MAX_FRAMES:
        raise InputError(f"{path.name} gives {n_frames} frames at {fps:g} fps, more than {MAX_FRAMES}: "
                         "shorten the animation")

    parent = _node_parents(path.name, nodes)
    scenes = doc.get("scenes") or [{"nodes": [i for i in range(len(nodes)) if i not in parent]}]
    roots = scenes[int(doc.get("scene", 0))].get("nodes", [])
    in_scene, stack, seen = [], [int(r) for r in roots], set()
    while stack:
        i = stack.pop()
        if i in seen:  # a root listed twice, or below another root
            continue
        seen.add(i)
        in_scene.append(i)
        stack += [int(c) for c in nodes[i].get("children", [])]

    def local(i: int, t: float) -> np.ndarray:
        n = nodes[i]
        if "matrix" in n and not any((i, p) in channels for p in ("translation", "rotation", "scale")):
            return np.array(n["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major
        tr = channels[(i, "translation")].at(t) if (i, "translation") in channels else np.array(n.get("translation", [0, 0, 0]), float)
        ro = channels[(i, "rotation")].at(t) if (i, "rotation") in channels else np.array(n.get("rotation", [0, 0, 0, 1]), float)
        sc = channels[(i, "scale")].at(t) if (i, "scale") in channels else np.array(n.get("scale", [1, 1, 1]), float)
        m = np.eye(4)
        m[:3, :3] = _quat_matrix(ro) * sc[None, :]
        m[:3, 3] = tr
        return m

    # the mesh primitives (static parts read once)
    prims = []
    offset = 0
    faces = []
    for i in in_scene:
        n = nodes[i]
        if "mesh" not in n:
            continue
        mesh = doc["meshes"][n["mesh"]]
        skin = doc["skins"][n["skin"]] if "skin" in n else None
        for p in mesh.get("primitives", []):
            if p.get("mode", 4) != 4:
                continue
            if "POSITION" not in p.get("attributes", {}):
                continue
            if "extensions" in p and "KHR_draco_mesh_compression" in p["extensions"]:
                raise InputError(f"{path.name}: Draco-compressed meshes are not read; export without compression")
            pos = f.accessor(p["attributes"]["POSITION"])
            idx = f.accessor(p["indices"])[:, 0].astype(np.int64) if "indices" in p else np.arange(len(pos))
            if len(idx) % 3 or (len(idx) and (idx.min() < 0 or idx.max() >= len(pos))):
                raise InputError(f"{path.name}: a primitive's triangle indices are malformed")
            targets = [f.accessor(t["POSITION"]) for t in p.get("targets", []) if "POSITION" in t]
            default_w = np.array(n.get("weights", mesh.get("weights", [0.0] * len(p.get("targets", [])))), float)
            joints = weights = None
            if skin is not None:
                sets = sorted(k for k in p["attributes"] if k.startswith("JOINTS_"))
                if sets:
                    joints = np.concatenate([f.accessor(p["attributes"][k]) for k in sets], axis=1).astype(np.int64)
                    weights = np.concatenate([f.accessor(p["attributes"]["WEIGHTS_" + k[7:]]) for k in sets], axis=1)
                    s = weights.sum(axis=1, keepdims=True)
                    weights = weights / np.where(s > 0, s, 1.0)
                    if joints.max() >= len(skin["joints"]):
                        raise InputError(f"{path.name}: a vertex names joint {joints.max()}, the skin has "
                                         f"{len(skin['joints'])}")
            prims.append((i, pos, targets, default_w, skin, joints, weights))
            if len(prims) > MAX_PARTS:
                raise InputError(f"{path.name} has more than {MAX_PARTS} mesh parts: a body is one mesh (or a few); "
                                 "merge them on export")
            faces.append(idx.reshape(-1, 3) + offset)
            offset += len(pos)
    if not prims:
        raise InputError(f"{path.name} contains no triangle mesh")
    if n_frames * offset * 3 > MAX_VALUES:
        raise InputError(f"{path.name}: {n_frames} frames of {offset:,} vertices are too many to sample: "
                         "shorten the animation, lower the frame rate or decimate the mesh")
    ibm_cache = {}

    frames = np.empty((n_frames, offset, 3))
    for k in range(n_frames):
        t = k / fps
        world: dict[int, np.ndarray] = {}

        def glob(i: int) -> np.ndarray:
            if i not in world:
                m = local(i, t)
                world[i] = glob(parent[i]) @ m if i in parent else m
            return world[i]

        row = 0
        for node, pos, targets, default_w, skin, joints, weights in prims:
            v = pos.copy()
            if targets:
                w = channels[(node, "weights")].at(t) if (node, "weights") in channels else default_w
                for j, d in enumerate(targets[:len(w)]):
                    if w[j] != 0.0:
                        v += w[j] * d
            if skin is not None and joints is not None:
                key = id(skin)
                if key not in ibm_cache:
                    js = skin["joints"]
                    ibm_cache[key] = (f.accessor(skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
                                      if "inverseBindMatrices" in skin else np.tile(np.eye(4), (len(js), 1, 1)))
                jm = np.stack([glob(int(j)) for j in skin["joints"]]) @ ibm_cache[key]  # (J, 4, 4)
                vh = np.concatenate([v, np.ones((len(v), 1))], axis=1)
                out = np.zeros((len(v), 3))
                for c in range(joints.shape[1]):
                    out += weights[:, c:c + 1] * np.einsum("nij,nj->ni", jm[joints[:, c], :3, :], vh)
                v = out
            else:
                g = glob(node)
                v = v @ g[:3, :3].T + g[:3, 3]
            frames[k, row:row + len(v)] = v
            row += len(v)
        if not np.all(np.isfinite(frames[k])):
            raise InputError(f"{path.name}: frame {k} ({t:.2f} s) has non-finite vertex positions")
    notes.append(f"{path.name}: {len(prims)} mesh part(s), {offset} vertices, animation of {end:.2f} s sampled at "
                 f"{fps:g} fps ({n_frames} frames)")
    return frames, np.concatenate(faces), notes
