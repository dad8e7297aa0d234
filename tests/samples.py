"""Where the shared sample inputs are: ../shared/samples beside the repository (as in CI)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT.parent / "shared" / "samples" / "garmentcode"
SAMPLE_BODY = SAMPLES / "mean_female.obj"
SAMPLE_YAML = SAMPLES / "mean_female.yaml"
SAMPLE_SKIRT = SAMPLES / "flare_skirt_specification.json"
