#!/usr/bin/env bash
# Build MolmoSpaces' own virtual environment for the differential tests (tests/parity, docs/parity.md):
# Python 3.12, the pinned requirements in tests/parity/requirements.txt, then molmo-spaces itself.
# Usage: scripts/parity-venv.sh [VENV_DIR]   (default .parity-venv; rebuilt from scratch each time)
set -euo pipefail
cd "$(dirname "$0")/.."
VENV_DIR=${1:-.parity-venv}
MOLMO_SPACES=molmo-spaces==0.2.9
RESOURCES=molmospaces-resources==0.0.2

PY312=${PYTHON312:-$(scripts/find-python312.sh)}
pip_install() {  # quiet, minus the notes about this machine's unreachable extra indexes
  "$VENV_DIR/bin/python" -m pip install -q --disable-pip-version-check "$@" 2>&1 | { grep -v "^WARNING: Location" || true; }
}
rm -rf "$VENV_DIR"
"$PY312" -m venv "$VENV_DIR"
pip_install --upgrade pip
pip_install -r tests/parity/requirements.txt
pip_install --no-deps "$MOLMO_SPACES" "$RESOURCES"  # --no-deps: see tests/parity/requirements.txt
"$VENV_DIR/bin/python" -c "import molmo_spaces, mujoco; print('parity venv $VENV_DIR: molmo_spaces at', molmo_spaces.__file__, '| mujoco', mujoco.__version__)"
