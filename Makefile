# Set-up is two commands on a fresh machine: `make eval` and `make test`.
SHELL := /bin/bash
VENV := .venv
# LIBERO's own venv (robosuite 1.4 beside our 1.5): the LIBERO suite and its parity tests (docs/suites.md).
LIBERO_VENV := .libero-venv
# ALOHA's own venv (gym-aloha's dm-control pins mujoco 3.8.1 beside our 3.5.0): the ALOHA suite (docs/suites.md).
ALOHA_VENV := .aloha-venv
PY := $(VENV)/bin/python
export MUJOCO_GL ?= egl

# Python 3.12: on PATH, else through pyenv (see scripts/find-python312.sh).
PYTHON312 ?= $(shell scripts/find-python312.sh)

# Plugin distributions to install; the example plugin is installed by its own test instead.
PLUGINS := $(filter-out plugins/molmo-example-%,$(wildcard plugins/*/pyproject.toml))

.PHONY: eval test test-all typecheck perf perf-gpu parity parity-libero train-demo clean

$(VENV): pyproject.toml $(PLUGINS)
	@test -n "$(PYTHON312)" || { echo "Python 3.12 not found (PATH or pyenv)"; exit 1; }
	@echo "using $(PYTHON312)"
	test -x $(PY) || $(PYTHON312) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip 2>&1 | grep -v "^WARNING: Location" || true
	$(PY) -m pip install -q -e ".[test,ray,training,viz]" $(foreach p,$(dir $(PLUGINS)),-e ./$(p)) 2>&1 | grep -v "^WARNING: Location"; test $${PIPESTATUS[0]} -eq 0
	@# molmo-pi0's in-process mode (LeRobot's PI0/PI0.5: transformers), so its random-init checkpoint test runs
	$(PY) -m pip install -q -e "./plugins/molmo-pi0[inprocess]" 2>&1 | grep -v "^WARNING: Location"; test $${PIPESTATUS[0]} -eq 0
	@# franka_droid reads robosuite's Robotiq 2F-85 MJCF and meshes from its install path and never
	@# imports it, so none of its own requirements are wanted (one pins an old mink).
	$(PY) -m pip install -q --no-deps "robosuite>=1.5,<1.6" 2>&1 | grep -v "^WARNING: Location"; test $${PIPESTATUS[0]} -eq 0
	@# franka_droid_fr3 reads franky-sim's FR3 MJCF and meshes (Menagerie's franka_fr3, Apache-2.0) the same
	@# way; its simulator's requirements (pin, coal) are not wanted.
	$(PY) -m pip install -q --no-deps "franky-sim==1.0.4" 2>&1 | grep -v "^WARNING: Location"; test $${PIPESTATUS[0]} -eq 0
	@# LeRobot's PushT suite: gym-pusht requires opencv-python, whose cv2 would overwrite the cv2 of the
	@# opencv-python-headless LeRobot and we use; its other requirements (pymunk, pygame) are in pyproject.toml.
	$(PY) -m pip install -q --no-deps "gym-pusht==0.1.8" 2>&1 | grep -v "^WARNING: Location"; test $${PIPESTATUS[0]} -eq 0
	@# LeRobot decodes video with torchcodec when it is installed, else PyAV. torchcodec needs the
	@# system's FFmpeg shared libraries; where they are missing it fails to load and LeRobot prints
	@# a traceback before falling back. Removing it lets LeRobot pick PyAV by its own rule.
	@$(PY) -c "import torchcodec" >/dev/null 2>&1 || { \
	  echo "torchcodec cannot load here (no FFmpeg shared libraries): removing it, LeRobot will decode with PyAV"; \
	  $(PY) -m pip uninstall -q -y torchcodec; }
	touch $(VENV)

eval: $(VENV)
	$(VENV)/bin/molmo-eval policy=scripted benchmark=pick_v1 workers=2

# The default run in TEST_WORKERS pytest-xdist processes, a test file per process at a time (module
# fixtures are built once); TEST_WORKERS=0 runs it in this process.
TEST_WORKERS ?= 2
test: $(VENV) $(LIBERO_VENV) $(ALOHA_VENV)
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile

test-all: $(VENV) $(LIBERO_VENV) $(ALOHA_VENV)
	$(PY) -m pytest -q -m "slow or not slow"

# mypy over src/ ([tool.mypy] in pyproject.toml); tests/test_types.py runs the same in make test.
typecheck: $(VENV)
	$(PY) -m mypy

perf: $(VENV)
	$(PY) -m pytest -q -s -m perf tests/perf

# The same tables on a machine with an NVIDIA GPU: policies on cuda, MuJoCo rendering through EGL on the GPU.
perf-gpu: $(VENV)
	@nvidia-smi -L >/dev/null 2>&1 || { echo "perf-gpu: no NVIDIA GPU here (nvidia-smi -L failed); make perf runs on CPU"; exit 1; }
	MOLMO_PERF_DEVICE=cuda MUJOCO_GL=egl $(PY) -m pytest -q -s -m perf tests/perf

# Differential tests against MolmoSpaces' own code, in its own venv (docs/parity.md).
PARITY_VENV := .parity-venv
$(PARITY_VENV): scripts/parity-venv.sh tests/parity/requirements.txt
	PYTHON312=$(PYTHON312) scripts/parity-venv.sh $(PARITY_VENV)
	touch $(PARITY_VENV)

# Built by scripts/libero-venv.sh: LIBERO's packages there, the rest read from $(VENV).
$(LIBERO_VENV): $(VENV) scripts/libero-venv.sh tests/suites/libero-requirements.txt
	PYTHON312=$(PYTHON312) scripts/libero-venv.sh $(LIBERO_VENV) $(VENV)
	touch $(LIBERO_VENV)

# Built by scripts/aloha-venv.sh: gym-aloha, dm-control and their mujoco there, the rest read from $(VENV).
$(ALOHA_VENV): $(VENV) scripts/aloha-venv.sh tests/suites/aloha-requirements.txt
	PYTHON312=$(PYTHON312) scripts/aloha-venv.sh $(ALOHA_VENV) $(VENV)
	touch $(ALOHA_VENV)

parity: $(VENV) $(PARITY_VENV)
	MOLMO_PARITY_REQUIRED=1 $(PY) -m pytest -q -m parity tests/parity

# LIBERO against lerobot-eval: 50 episodes across the five suites in both reset modes, and every task's
# model built from the registry assets (hours on 2 CPU cores; make test runs the two-episode case).
parity-libero: $(VENV) $(LIBERO_VENV)
	$(PY) -m pytest -q -s -m slow tests/suites/test_libero_parity.py

# Expert recordings -> lerobot-train ACT -> trained vs random on pick_v1 (knobs: scripts/train_demo.sh).
train-demo: $(VENV)
	PYTHON=$(PY) scripts/train_demo.sh

clean:
	rm -rf $(VENV) $(PARITY_VENV) $(LIBERO_VENV) $(ALOHA_VENV) outputs runs .mypy_cache
