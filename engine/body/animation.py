"""An uploaded animated body at a stated frame rate -> BodyTrack: a zip of OBJ frames (one
topology), or a glTF 2.0 file (.glb) with morph-target or skinned animation.

    track = load_animation("walk.zip", fps=30)
    track = load_animation("walk.glb", fps=30)     # sampled at 1/30 s (engine.body.gltf_anim)

Zip frames are the zip's .obj entries in name order (frame_000.obj, frame_001.obj, ...). The first
frame is loaded as a scan (engine.body.load: units, axes, repairs) and the same transform is
applied to every frame, so the body keeps its motion through the room; vertices the repair
dropped or merged are mapped by position in the first frame. Velocities are central
differences of the frames. Segment labels come from fitting the default skeleton to the first
frame (engine.body.fit) when it stands in an A-pose, else the maps are whole-body.
"""

from __future__ import annotations

import tempfile
import zipfile
from pathlib import Path

import numpy as np

from engine.body.load import _read, load_body_file
from engine.body.motion import BodyTrack, frame_velocities
from engine.body.types import Body
from engine.errors import InputError, parser

MAX_FRAMES = 3000
MAX_UNZIPPED = 2 * 2 ** 30  # bytes of OBJ frames a zip may expand to
MAX_RATIO = 100  # expanded / compressed size of a member (OBJ text compresses ~5-10 x)


@parser("an animation")
def load_animation(path: str | Path, fps: float, up: str | None = None, front: str | None = None) -> BodyTrack:
    path = Path(path)
    if not (5.0 <= fps <= 240.0):
        raise InputError(f"frame rate {fps} is out of range (5 .. 240 frames per second)")
    if not path.is_file():
        raise InputError(f"animation file not found: {path}")
    if path.suffix.lower() in (".glb", ".gltf"):
        from engine.body.gltf_anim import sample_gltf_animation

        frames_raw, faces0, notes = sample_gltf_animation(path, fps)
        if len(frames_raw) > MAX_FRAMES:
            raise InputError(f"{path.name} gives {len(frames_raw)} frames at {fps:g} fps, more than {MAX_FRAMES}: "
                             "shorten the animation")
        with tempfile.TemporaryDirectory() as tmp:
            p0 = Path(tmp) / "frame0.obj"  # the first frame is loaded as a scan (units, axes, repairs)
            with open(p0, "w") as fh:
                fh.write("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in frames_raw[0].tolist()))
                fh.write("".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces0.tolist()))
            first = load_body_file(p0, up=up, front=front, fill_holes=False)
        names = [f"{path.name} frame {k}" for k in range(len(frames_raw))]
        return _track(path, first, list(frames_raw), names, fps, notes)
    if not zipfile.is_zipfile(path):
        raise InputError(f"{path.name} is not a zip file: an animated body is a zip of OBJ frames (one per frame, "
                         "same vertices in the same order) or a .glb with an animation")
    with zipfile.ZipFile(path) as z, tempfile.TemporaryDirectory() as tmp:
        names = sorted(n for n in z.namelist() if n.lower().endswith(".obj") and not n.endswith("/"))
        if len(names) < 2:
            raise InputError(f"{path.name} holds {len(names)} OBJ frame(s): an animation needs at least 2")
        if len(names) > MAX_FRAMES:
            raise InputError(f"{path.name} holds {len(names)} frames, more than {MAX_FRAMES}: shorten the animation")
        _check_sizes(path.name, [z.getinfo(n) for n in names])
        files = []
        for i, n in enumerate(names):
            p = Path(tmp) / f"{i:05d}.obj"  # our own names: never a path from the zip
            p.write_bytes(z.read(n))
            files.append(p)
        first = load_body_file(files[0], up=up, front=front, fill_holes=False)
        raw0, faces0 = _read(files[0])
        frames_raw = [raw0]
        for n, p in zip(names[1:], files[1:]):
            v, f = _read(p)
            if v.shape != raw0.shape or f.shape != faces0.shape or not np.array_equal(f, faces0):
                raise InputError(f"frame '{n}' has {len(v)} vertices / {len(f)} triangles, the first frame "
                                 f"{len(raw0)} / {len(faces0)}: every frame needs the same mesh topology")
            frames_raw.append(v)
    return _track(path, first, frames_raw, names, fps, [])


def _check_sizes(name: str, members: list) -> None:
    """Refuse a zip bomb before extracting: the sizes its directory states (zipfile reads no more
    than a member's stated size) in total and against each member's compressed size."""
    total = sum(m.file_size for m in members)
    if total > MAX_UNZIPPED:
        raise InputError(f"{name} expands to {total / 2 ** 30:.1f} GiB, more than {MAX_UNZIPPED / 2 ** 30:.0f}: "
                         "send fewer or smaller frames")
    for m in members:
        if m.file_size > MAX_RATIO * max(m.compress_size, 1024):
            raise InputError(f"{name}: '{m.filename}' expands {m.file_size / max(m.compress_size, 1):.0f} times: "
                             "not an OBJ frame (a zip bomb?)")


def _track(path: Path, first: Body, frames_raw: list, names: list[str], fps: float, notes: list[str]) -> BodyTrack:
    """The frames (file coordinates) moved like the first frame was when it was loaded as a scan."""
    raw0 = frames_raw[0]
    a = first.to_world
    world0 = raw0 @ a[:3, :3].T + a[:3, 3]
    from scipy.spatial import cKDTree

    dist, index = cKDTree(world0).query(first.vertices)
    if dist.max() > 1e-6:
        raise InputError(f"{path.name}: the first frame could not be matched to its repaired mesh")
    frames = np.empty((len(frames_raw), len(first.vertices), 3), np.float32)
    for k, v in enumerate(frames_raw):
        with np.errstate(over="ignore", invalid="ignore"):
            frames[k] = v[index] @ a[:3, :3].T + a[:3, 3]
        if not np.all(np.isfinite(frames[k])):  # checked in float32: finite float64 may overflow it
            raise InputError(f"frame '{names[k]}' has non-finite vertex positions")
    vel = frame_velocities(frames, fps)
    speed = np.linalg.norm(vel, axis=2).max()
    if speed > 20.0:
        raise InputError(f"{path.name}: a body point moves at {speed:.0f} m/s between frames: is --fps right, or are "
                         "frames out of order?")
    body = Body(vertices=frames[0].astype(np.float64), faces=first.faces, name=path.stem, notes=list(first.notes),
                to_world=first.to_world)
    notes = notes + [f"animation: {len(frames)} frames at {fps:g} fps ({(len(frames) - 1) / fps:.2f} s) from {path.name}"]
    try:
        from engine.body.fit import fit_rig

        body.segments = fit_rig(body).segments
    except InputError as e:
        notes.append(f"segment maps, because the first frame could not be segmented ({e})")
    return BodyTrack(body=body, fps=float(fps), frames=frames, vel=vel, offsets=np.zeros((len(frames), 3)),
                     cycle_start=0, cycle_frames=0, shift=np.zeros(3), notes=notes)
