#!/usr/bin/env bash
# One-time (idempotent) set-up on Debian 12 as root: OpenGL system libraries, a virtual
# environment and the pinned Python packages. Fast when already done (a stamp file records
# the hash of the lock files).
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PKGS=(libosmesa6 libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0 libgbm1 libglx-mesa0
          chromium libcairo2)  # chromium: the browser test (Playwright drives Debian's, never downloads one);
          # libcairo2: GarmentCode's design sampler (its benchmark and tests) draws through cairosvg
missing=()
for p in "${APT_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" -ne 0 ]; then
    echo "setup: need root to install: ${missing[*]} (apt-get install -y ${missing[*]})" >&2
    exit 1
  fi
  echo "setup: installing system packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating virtual environment .venv"
  "$PY" -m venv .venv
fi
stamp=.venv/.tryon-setup
want=$(cat requirements.lock requirements-nodeps.lock pyproject.toml | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setup: installing Python packages (pinned, requirements.lock)"
  .venv/bin/python -m pip install -q --disable-pip-version-check -r requirements.lock
  .venv/bin/python -m pip install -q --disable-pip-version-check --no-deps -r requirements-nodeps.lock
  .venv/bin/python -m pip install -q --disable-pip-version-check --no-deps -e .
  echo "$want" > "$stamp"
fi
