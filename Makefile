# Two commands do all the set-up from a fresh clone:
#   make demo   creates .venv, installs windseek, runs SITL + estimator + search mission (windseek demo)
#   make test   creates .venv, installs windseek with its test extras, runs the test suite
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: demo test test-fast venv bench lint clean

$(BIN)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e ".[test]"
	touch $@

venv: $(BIN)/.installed

# SITL + wind estimator + MAVSDK search mission as three MAVLink processes; logs/<time>-*.rrd/.tlog/.json
demo: venv
	$(BIN)/windseek demo

# Two test processes (pytest-xdist, work stealing): the end-to-end tests mostly wait on paced clocks, so
# two of them share the 2 cores well; each worker hands out ports from its own slice (tests/link_support.py).
test: venv
	$(BIN)/python -m pytest -q -n 2 --dist worksteal --durations=15

# The fast suite alone: everything but the end-to-end tests (processes, MAVSDK, MAVProxy).
test-fast: venv
	$(BIN)/python -m pytest -q -m "not e2e"

bench: venv
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e ".[test,bench]"
	$(BIN)/python benchmarks/sim_speed.py

# Style, types (mypy, configured in pyproject.toml) and the house rules (import cycles, layering, file sizes).
lint: venv
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/python -m pytest -q tests/test_architecture.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
