"""Where the shared sample inputs are: ../shared/samples beside the repository (as in CI)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT.parent / "shared" / "samples" / "garmentcode"
SAMPLE_BODY = SAMPLES / "mean_female.obj"
SAMPLE_YAML = SAMPLES / "mean_female.yaml"
SAMPLE_SKIRT = SAMPLES / "flare_skirt_specification.json"
DXF_SAMPLES = ROOT.parent / "shared" / "samples" / "dxf"  # real pattern-CAD exports (their README)
# GarmentCode's own T-shirt (tests/garmentcode/README.md): a sleeved pattern file
GC_SHIRT = ROOT / "tests" / "garmentcode" / "shirt_mean_specification.json"


def write_anim_zip(path, frames, faces, names=None):
    """An uploaded animation: a zip of OBJ frames (vertices (V, 3) per frame, shared faces)."""
    import io
    import zipfile

    with zipfile.ZipFile(path, "w") as z:
        for k, v in enumerate(frames):
            buf = io.StringIO()
            buf.write("".join(f"v {x:.6f} {y:.6f} {zz:.6f}\n" for x, y, zz in v))
            buf.write("".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces))
            z.writestr(names[k] if names else f"frames/f_{k:03d}.obj", buf.getvalue())
    return path


def write_arms_lowered_scan(path, degrees: float):
    """default:female with its upper arms turned `degrees` towards the body, saved as an OBJ
    scan (no skeleton, no segment labels): at 20 degrees its arms hang 5.4 cm from the torso
    10 cm below the armpits, at 30 degrees 2.4 cm (the A-pose: 12.7 cm)."""
    import trimesh

    from engine.body import resolve_body
    from engine.body.motion import _rot, pose_joints
    from engine.body.rig import skin

    a_pose = resolve_body("default:female")
    posed = skin(a_pose.vertices, a_pose.rig, pose_joints(a_pose.rig, {"upperarm01.L": _rot("z", -degrees),
                                                                       "upperarm01.R": _rot("z", degrees)}))
    trimesh.Trimesh(posed, a_pose.faces, process=False).export(path)
    return path


def set_engine_env(mp, **env):
    """Set TRYON_* variables for one test (pytest's monkeypatch `mp`) and make the engine read
    its settings again (engine.settings keeps what it read; `mp` restores both afterwards)."""
    import engine.settings

    for k, v in env.items():
        mp.setenv(k, v)
    mp.setattr(engine.settings, "_current", None)
