#!/usr/bin/env bash
# Install everything colourhs needs on a Debian machine into ./.venv.
# Idempotent: a second run only checks. Needs root (or sudo) for apt-get
# when system libraries are missing.
set -euo pipefail
cd "$(dirname "$0")/.."

# System libraries that open3d (the pipeline) and pymeshlab (test-only: the test
# extra's MeshLab reference, tests/evaluation/test_accuracy.py) load, and venv support.
pkgs=(libusb-1.0-0 libgl1 libegl1 libx11-6 libudev1 libglib2.0-0 libgomp1)
# Headless Chromium for the report's browser test (tests/report/test_report_browser.py).
pkgs+=(chromium)
py=$(command -v python3.11 || command -v python3)
if ! "$py" -m venv --help >/dev/null 2>&1 || ! "$py" -c "import ensurepip" >/dev/null 2>&1; then
  pkgs+=(python3-venv)
fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing system packages: ${missing[*]}"
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv with $py"
  "$py" -m venv .venv
fi
stamp=.venv/.colourhs-installed
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setup: installing colourhs and its dependencies into .venv"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e '.[test]'
  echo "$want" > "$stamp"
fi
# pymeshlab is no dependency of the pipeline (its evaluation uses open3d) but of the
# test extra installed above (.[test]): the tests compare the distances against it.
.venv/bin/python -c "import open3d, pymeshlab, cv2, numba, colourhs" \
  || { echo "setup: the environment does not import; remove .venv and rerun" >&2; exit 1; }
echo "setup: ready (.venv)"
