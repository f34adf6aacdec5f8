# motor_comp — the two commands of the README: `make demo` and `make test`.
# Both create the virtual environment and install everything the project needs
# (library, ROS 2 Jazzy wheels from PyPI, test and bench tools) on a fresh machine.
PYTHON ?= python3
VENV   ?= .venv
PY      = $(VENV)/bin/python
STAMP   = $(VENV)/.motor_comp-installed
# DDS traffic stays on this machine (tests/demos start real nodes).
export ROS_AUTOMATIC_DISCOVERY_RANGE = LOCALHOST
export RMW_IMPLEMENTATION ?= rmw_fastrtps_cpp

.PHONY: setup demo test lint bench stress clean

$(STAMP): setup.py setup.cfg package.xml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[ros,test,bench,cluster]'
	# byte-compile the package as a regular (non-editable) pip install does: every
	# command then loads it without recompiling ~60 modules (~0.1 s a call where the
	# environment sets PYTHONDONTWRITEBYTECODE)
	$(PY) -m compileall -q motor_comp > /dev/null
	touch $(STAMP)

# the kernels `fit`/`diagnose` call from Python, compiled ahead of time (numba.pycc, C
# compiler): a command then never starts numba's JIT (0.55-0.85 s of CPU a command,
# measured); rebuilt when a source it inlines changes. If it cannot be built the
# commands use the JIT, as before.
AOT_STAMP = motor_comp/physics/_aot_kernels.stamp
AOT_SOURCES = $(wildcard motor_comp/physics/*.py motor_comp/physics/effects/*.py \
                         motor_comp/workbench/*.py)

# the ahead-of-time build keeps one core busy for about a minute from a fresh clone; the
# other fills numba's cache of the simulator's loop and the controller's step meanwhile
# (about 30 s of compiling the first test or node would otherwise do)
$(AOT_STAMP): $(STAMP) $(AOT_SOURCES)
	-$(PY) -m motor_comp.control.warm & $(PY) -m motor_comp.physics.aot_build; wait

setup: $(STAMP) $(AOT_STAMP)

demo: $(STAMP) $(AOT_STAMP)
	$(PY) -m motor_comp.cli.main demo --out demo_out

# two workers, one test file each at a time (--dist loadfile: a module's fixtures are
# computed once), CPU-bound workbench files beside the node tests, the longest files
# first (test/conftest.py LONGEST_FIRST; --no-loadscope-reorder keeps that order); then
# the tests that need the machine to themselves (wall-clock timing, marker `alone`)
test: $(STAMP) $(AOT_STAMP)
	$(PY) -m pytest -q -p no:cacheprovider -n 2 --dist loadfile --no-loadscope-reorder -m 'not alone' test
	$(PY) -m pytest -q -p no:cacheprovider -m alone test

lint: $(STAMP)
	$(PY) -m flake8 motor_comp test bench launch setup.py
	$(PY) -m pydocstyle motor_comp

bench: $(STAMP) $(AOT_STAMP)
	$(PY) bench/run_all.py

# node tests N times in a row while two CPU-bound processes load both cores
stress: $(STAMP)
	test/stress_nodes.sh $(or $(N),30)

clean:
	rm -rf build install log demo_out .pytest_cache
	find motor_comp -name '*.nbi' -o -name '*.nbc' | xargs rm -f
	rm -f motor_comp/physics/_aot_kernels.*
