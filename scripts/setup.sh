#!/usr/bin/env bash
# One-time (and idempotent, quick when nothing changed) setup of the project:
#   1. the system library open3d needs (Debian package libusb-1.0-0);
#   2. a virtual environment in .venv with the exact pins of requirements.lock;
#   3. the project itself, editable, into that environment.
# Usage: bash scripts/setup.sh      (called by `make setup`, `make test`, `make reproduce`)
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3.11}
command -v "$PYTHON" >/dev/null 2>&1 || PYTHON=python3
VENV=.venv
STAMP=$VENV/.setup-stamp

# --- 1. system library -------------------------------------------------------------------
if ! ldconfig -p 2>/dev/null | grep 'libusb-1.0.so.0' >/dev/null; then  # not -q: SIGPIPE + pipefail
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "[setup] installing Debian package libusb-1.0-0 (needed by open3d)"
    (apt-get install -y -qq libusb-1.0-0 >/dev/null 2>&1) || \
      (apt-get update -qq >/dev/null && apt-get install -y -qq libusb-1.0-0 >/dev/null)
  else
    echo "[setup] ERROR: the system library libusb-1.0 is missing; open3d cannot be imported without it." >&2
    echo "[setup]        Install it as root:  sudo apt-get install libusb-1.0-0   and run this again." >&2
    exit 1
  fi
fi

# --- 2./3. virtual environment -------------------------------------------------------------
want=$(cat requirements.lock pyproject.toml | sha256sum | cut -d' ' -f1)
if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$want" ] && [ -x $VENV/bin/python ]; then
  echo "[setup] .venv is up to date"
  exit 0
fi
"$PYTHON" -c 'import sys; sys.exit(0 if sys.version_info[:2] == (3, 11) else 1)' || {
  echo "[setup] ERROR: Python 3.11 is required (found $("$PYTHON" --version 2>&1)); set PYTHON=/path/to/python3.11" >&2
  exit 1
}
[ -x $VENV/bin/python ] || "$PYTHON" -m venv $VENV
echo "[setup] installing pinned packages into $VENV (first time: a few minutes, about 3 GB)"
# (this machine's pip config lists local indexes that may not exist: hide those warnings only)
quiet_pip() { $VENV/bin/python -m pip --disable-pip-version-check "$@" 2> >(grep -v 'WARNING: Location' >&2); }
quiet_pip install --quiet -r requirements.lock
quiet_pip install --quiet --no-deps --no-build-isolation -e .
$VENV/bin/python -c "import pybullet, torch, open3d, cv2, rerun, mcap, foxglove, hydra, ray" \
  || { echo "[setup] ERROR: the environment was installed but an import failed (see above)." >&2; exit 1; }
$VENV/bin/rerun analytics disable >/dev/null 2>&1 || true
echo "$want" > "$STAMP"
echo "[setup] done"
