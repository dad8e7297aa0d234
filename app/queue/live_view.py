"""The live 3D view of a running try-on: a viser server (loopback, a free port) in the worker
process, fed by the engine's observer with the body and the cloth as they are simulated, and
recorded into a .viser file that the page plays back once the try-on is done. FastAPI relays the
viewer at /viewer/{job} (app/api/routes/viewer.py)."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np

BODY_RGB = (204, 173, 148)
GARMENT_RGB = (70, 110, 190)
MIN_INTERVAL = 0.1  # s of wall time between live updates (the viewer is a picture, not the solver)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class LiveView:
    def __init__(self, body_vertices: np.ndarray, body_faces: np.ndarray, port: int | None = None):
        import viser

        self.server = viser.ViserServer(host="127.0.0.1", port=port or free_port(), verbose=False)
        self.port = int(self.server.get_port())
        self.server.scene.set_up_direction("+y")
        top = float(np.asarray(body_vertices)[:, 1].max())
        self.server.initial_camera.position = (1.2, 0.75 * top, 2.6)  # in front, a little to the side
        self.server.initial_camera.look_at = (0.0, 0.55 * top, 0.0)
        self.recording = self.server.get_scene_serializer()
        self.body = self.server.scene.add_mesh_simple("/body", np.asarray(body_vertices, np.float32),
                                                      np.asarray(body_faces, np.uint32), color=BODY_RGB)
        self.garment = None
        self.faces = None
        self.n_vertices = -1
        self.last = 0.0
        self.frames = 0

    def __call__(self, stage: str, positions: np.ndarray, triangles: np.ndarray, body_vertices=None) -> None:
        now = time.monotonic()
        walking = stage == "walking"
        if not walking and now - self.last < MIN_INTERVAL:
            return
        if self.frames:
            self.recording.insert_sleep(1 / 30 if walking else MIN_INTERVAL)
        self.last = now
        v = np.asarray(positions, np.float32)
        if self.garment is None or triangles is not self.faces or len(v) != self.n_vertices:
            # a new mesh (welding the seams merges vertices: same face count, other indices);
            # a node added under the same name replaces the old one -- also in the recording,
            # where a remove() + add was played back with both meshes shown
            self.faces, self.n_vertices = triangles, len(v)
            self.garment = self.server.scene.add_mesh_simple("/garment", v, np.asarray(triangles, np.uint32),
                                                             color=GARMENT_RGB, side="double")
        else:
            self.garment.vertices = v
        if body_vertices is not None:
            self.body.vertices = np.asarray(body_vertices, np.float32)
        self.frames += 1

    def save(self, path: Path) -> Path:
        path.write_bytes(self.recording.serialize())
        return path

    def close(self) -> None:
        self.server.stop()
