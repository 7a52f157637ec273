#!/usr/bin/env bash
# Build the ALOHA suite's own virtual environment (src/molmo_lerobot/suites/aloha.py, docs/suites.md).
# gym-aloha (LeRobot's `aloha` extra) runs on dm-control 1.0.41, which pins mujoco 3.8.1, while this project's
# mujoco is MolmoSpaces' 3.5.0; so ALOHA gets a venv of its own: gym-aloha, dm-control and their mujoco there,
# everything else (LeRobot, torch, gymnasium, this project) read from the main venv through a .pth file.
# Usage: scripts/aloha-venv.sh [VENV_DIR] [MAIN_VENV]   (defaults .aloha-venv, .venv; rebuilt from scratch)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV_DIR=${1:-.aloha-venv}
MAIN_VENV=${2:-.venv}
PY312=${PYTHON312:-$(scripts/find-python312.sh)}
pip_install() {  # quiet, minus the notes about this machine's unreachable extra indexes
  "$VENV_DIR/bin/python" -m pip install -q --disable-pip-version-check "$@" 2>&1 | { grep -v "^WARNING: Location" || true; }
}
MAIN_SITE=$(cd "$MAIN_VENV" && echo "$PWD"/lib/python3.12/site-packages)
test -d "$MAIN_SITE" || { echo "aloha-venv: no main venv at $MAIN_VENV (run make .venv first)"; exit 1; }
rm -rf "$VENV_DIR"
"$PY312" -m venv "$VENV_DIR"
VENV_ABS=$(cd "$VENV_DIR" && pwd)
SITE="$VENV_ABS/lib/python3.12/site-packages"
pip_install --upgrade pip
# --no-deps: the pinned set of tests/suites/aloha-requirements.txt, nothing the main venv already provides.
pip_install --no-deps -r tests/suites/aloha-requirements.txt
# Appended after this venv's own site-packages (so its mujoco 3.8.1 wins over the main venv's), as a site dir,
# so the main venv's own .pth files (its editable installs) apply too.
echo "import site; site.addsitedir('$MAIN_SITE')" > "$SITE/zz_main_venv.pth"
MUJOCO_GL=${MUJOCO_GL:-egl} "$VENV_DIR/bin/python" -c \
  "import mujoco, gym_aloha, lerobot; print('aloha venv $VENV_DIR: mujoco', mujoco.__version__)" </dev/null
