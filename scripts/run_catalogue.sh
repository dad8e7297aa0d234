#!/usr/bin/env bash
# Drape every catalogue garment on both default bodies (size M, cotton) and the GarmentCode sample
# skirt on the sample body; pictures and reports under out/catalogue/. Prints one line per run.
set -u
cd "$(dirname "$0")/.."
OUT=${OUT:-out/catalogue}
mkdir -p "$OUT"
for body in female male; do
  for g in skirt trousers sleeveless-shirt dress shirt; do
    d="$OUT/${body}_${g}"
    line=$(timeout 900 .venv/bin/tryon drape --body "default:$body" --garment "$g" --size M --out "$d" 2>&1 | grep -v '^note' | tail -1)
    echo "$body $g: $line"
  done
done
d="$OUT/sample_skirt"
line=$(timeout 900 .venv/bin/tryon drape --body ../shared/samples/garmentcode/mean_female.obj \
  --garment ../shared/samples/garmentcode/flare_skirt_specification.json --out "$d" 2>&1 | grep -v '^note' | tail -1)
echo "sample skirt: $line"
