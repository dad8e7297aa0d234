"""Mesh exports: a GLB scene (body + garments, glTF's Y-up metres: no conversion needed) and
garment OBJ files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

BODY_RGBA = (204, 173, 148, 255)
GARMENT_RGBA = (70, 110, 190, 255)


def _mesh(vertices: np.ndarray, faces: np.ndarray, rgba, double_sided: bool) -> trimesh.Trimesh:
    mat = trimesh.visual.material.PBRMaterial(baseColorFactor=rgba, metallicFactor=0.0, roughnessFactor=0.9,
                                              doubleSided=double_sided)
    m = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int64), process=False)
    m.visual = trimesh.visual.TextureVisuals(material=mat)
    return m


def write_scene_glb(path: str | Path, body_vertices, body_faces, garments: list[tuple[str, np.ndarray, np.ndarray]]) -> Path:
    """garments: list of (name, vertices (N, 3), faces (F, 3)); garments are double-sided."""
    scene = trimesh.Scene()
    scene.add_geometry(_mesh(body_vertices, body_faces, BODY_RGBA, False), geom_name="body", node_name="body")
    for name, v, f in garments:
        scene.add_geometry(_mesh(v, f, GARMENT_RGBA, True), geom_name=name, node_name=name)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(scene.export(file_type="glb"))
    return path


def write_obj(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    m = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int64), process=False)
    path.write_text(trimesh.exchange.obj.export_obj(m, include_normals=True))
    return path
