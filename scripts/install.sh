#!/usr/bin/env bash
# Install slam2d into ./.venv with its system libraries (Debian/Ubuntu).
set -euo pipefail
cd "$(dirname "$0")/.."

# Shared libraries open3d loads at import time.
APT_PACKAGES="libgl1 libgomp1 libusb-1.0-0 libegl1"
missing=$(for p in $APT_PACKAGES; do dpkg -s "$p" >/dev/null 2>&1 || echo "$p"; done)
if [ -n "$missing" ] && command -v apt-get >/dev/null; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing
fi

PYTHON=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
# dev: the tests; viz: --viz of the Quick start. Ray is optional (slam2d ablate --executor ray):
# SLAM2D_EXTRAS=dev,viz,ray bash scripts/install.sh, as CI does.
.venv/bin/python -m pip install -q -c constraints.txt -e ".[${SLAM2D_EXTRAS:-dev,viz}]"
