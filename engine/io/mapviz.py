"""Pictures of collision maps, like seed 003's figures 3-5: depth as grey levels (near = dark),
normals as RGB = 0.5 n + 0.5 (a surface facing the camera is bluish), velocities as
RGB = 0.5 + 0.5 v / max|v|. Empty pixels are white; side-layer pixels (the tolerance ring,
maps.py) are tinted pink in the depth pictures so the ring is visible.

Images are flipped so that up is up (map row 0 is the bottom, as GL reads it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.collide.maps import KIND_BODY, KIND_EMPTY, KIND_SIDE, CollisionMaps

_WHITE = np.array([255, 255, 255], np.uint8)
_SIDE = np.array([255, 190, 190], np.uint8)
KINDS = ("front_depth", "back_depth", "front_normal", "back_normal",
         "front_velocity", "back_velocity")


def _to_u8(rgb: np.ndarray) -> np.ndarray:
    return (np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def map_images(maps: CollisionMaps, s: int = 0) -> dict[str, np.ndarray]:
    """The six pictures of map s: name (KINDS) -> (H, W, 3) uint8, top row = highest y."""
    kind = maps.kind_map(s)
    body, side, empty = kind == KIND_BODY, kind == KIND_SIDE, kind == KIND_EMPTY
    zf, zb = maps.front_depth(s), maps.back_depth(s)
    zs = np.concatenate([zf[body], zb[body]]) if body.any() else np.zeros(1)
    lo, hi = float(zs.min()), float(zs.max())
    span = max(hi - lo, 1e-9)
    out: dict[str, np.ndarray] = {}
    for name, z, g in (("front_depth", zf, (hi - zf) / span), ("back_depth", zb, (zb - lo) / span)):
        grey = np.where(body | side, 0.1 + 0.8 * np.nan_to_num(g, nan=1.0, posinf=1.0, neginf=1.0), 1.0)
        img = _to_u8(np.repeat(grey[..., None], 3, axis=2))
        img[side] = _SIDE
        out[name] = img
    for name, n in (("front_normal", maps.front_normal(s)), ("back_normal", maps.back_normal(s))):
        img = _to_u8(0.5 * n + 0.5)
        img[empty] = _WHITE
        out[name] = img
    for name, v in (("front_velocity", maps.front_velocity(s)), ("back_velocity", maps.back_velocity(s))):
        if v is None:                      # no velocity maps: a mid-grey silhouette
            img = np.full(kind.shape + (3,), 128, np.uint8)
        else:
            vmax = float(np.abs(v[~empty]).max()) if (~empty).any() else 0.0
            img = _to_u8(0.5 + 0.5 * v / max(vmax, 1e-12))
        img[empty] = _WHITE
        out[name] = img
    return {k: np.ascontiguousarray(im[::-1]) for k, im in out.items()}


def save_map_pngs(maps: CollisionMaps, out_dir: str | Path) -> list[Path]:
    """Write the six pictures of every map (prefixed by the segment name when there are
    segment maps) plus overview.png (one row per map, six columns). Returns the written paths."""
    from PIL import Image

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    per_map = []
    for s, name in enumerate(maps.names):
        imgs = map_images(maps, s)
        per_map.append((name, imgs))
        prefix = "" if maps.segment_ids[s] < 0 else f"{name}_"
        for k in KINDS:
            p = out_dir / f"{prefix}{k}.png"
            Image.fromarray(imgs[k]).save(p)
            written.append(p)
    p = out_dir / "overview.png"
    _overview(per_map, maps, p)
    written.append(p)
    return written


def _overview(per_map, maps: CollisionMaps, path: Path) -> None:
    """One row per map; columns front/back depth, front/back normal, front/back velocity."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = len(per_map)
    aspect = max(im["front_depth"].shape[1] / im["front_depth"].shape[0] for _, im in per_map)
    cell = 2.6
    fig, axes = plt.subplots(rows, 6, figsize=(6 * cell * min(max(aspect, 0.35), 1.5) + 0.4,
                                               rows * cell + 0.5), squeeze=False)
    for m, (name, imgs) in enumerate(per_map):
        for c, k in enumerate(("front_depth", "back_depth", "front_normal", "back_normal",
                               "front_velocity", "back_velocity")):
            ax = axes[m, c]
            ax.imshow(imgs[k], interpolation="nearest")
            ax.set_title(f"{name}: {k.replace('_', ' ')}", fontsize=7)
            ax.axis("off")
    vel = "" if maps.has_velocity else "; no velocity maps (grey)"
    fig.suptitle(f"collision maps, texel {maps.texel * 1000:.2f} mm, tol {maps.tol * 1000:.1f} mm, "
                 f"pink = side layer{vel}", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)
