# The two commands a newcomer needs: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# Test processes (pytest-xdist); each test file runs whole in one of them.
JOBS ?= 2

.PHONY: demo test bench venv clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev,experiments]'
	# numba's cache of the planner's kernels, once: a first plan compiling them (a minute or
	# more on a busy machine) would stall the demo, a service just started, or a timed test
	$(PY) -m planner_service warm
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) -m planner_service demo --out demo-out

# Timed tests (marker `alone`) run after the rest, by themselves: beside another test
# process on two cores their figures measure the neighbour, not the code. The slowest
# tests are listed at the end: the suite's budget is 15 minutes on two cores.
test: $(STAMP)
	$(PY) -m pytest -q -n $(JOBS) --dist loadfile -m 'not slow and not soak and not alone' --durations=15
	$(PY) -m pytest -q -m alone

bench: $(STAMP)
	$(PY) -m planner_service bench

clean:
	rm -rf $(VENV) demo-out .pytest_cache
