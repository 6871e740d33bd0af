# The README's two commands: `make demo` (set-up, then the main job) and `make test` (set-up, then
# the tests). Set-up is idempotent; see scripts/setup.sh.
# ROS 2 discovery stays on this machine unless the caller says otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

VENV := .venv
PY := $(VENV)/bin/python

.PHONY: setup demo test test-stress bench fault-table parameter-table clean

setup:
	@bash scripts/setup.sh

demo: setup
	@$(VENV)/bin/cdpr demo

# the test files spread over one worker process per core (pytest-xdist, whole files: their module
# fixtures and ROS domains stay in one process); TEST_WORKERS=0 runs them in this process
TEST_WORKERS ?= auto
export TEST_WORKERS

test: setup
	@$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile tests

# the tests while two busy loops load both cores (no test may depend on an idle machine)
test-stress: setup
	@bash scripts/test-stress.sh

# docs/faults.md: the faults the suite injects, tries, held and lost
fault-table: setup
	@$(PY) scripts/fault_table.py

parameter-table: setup
	@$(PY) scripts/parameter_table.py

bench: setup
	@$(VENV)/bin/cdpr bench

clean:
	rm -rf $(VENV) build
