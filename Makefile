# rabbit-hzd: two commands for a fresh machine (see README).
#   make demo   set up .venv if needed, then run the ROS 2 stack: RABBIT walks on the learned controller,
#               changing speed (down from 1.4 m/s too) and pushed, judged beside classic (scripts/demo.py)
#   make test   set up .venv if needed, then run the whole test suite (CI's command)
#   make test-fast  the edit-loop tier: every test not marked slow
#   make lint   ruff (pyflakes and pycodestyle; ruff.toml), as CI runs it
#   make bench  the benchmarks (simulation, ROS stack, training throughput), JSON lines
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# pytest-xdist workers for make test / test-fast (each its own ROS_DOMAIN_ID, tests/conftest.py);
# TEST_WORKERS=0 runs the suite in one process
TEST_WORKERS ?= 2
# where torch's CPU build comes from when the default index serves the CUDA one (requirements.txt)
TORCH_INDEX ?=
PACKAGES := src/rabbit_msgs_py src/rabbit_sim src/rabbit_hzd_controller src/rabbit_policy

export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: setup demo test test-fast lint bench clean

setup: $(STAMP)

$(STAMP): requirements.txt requirements-extras.txt $(foreach p,$(PACKAGES),$(p)/setup.py $(p)/package.xml)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(if $(TORCH_INDEX),$(PY) -m pip install --quiet torch==2.13.0 --index-url $(TORCH_INDEX))
	$(PY) -m pip install --quiet -r requirements.txt -r requirements-extras.txt
	$(PY) -m pip install --quiet $(foreach p,$(PACKAGES),-e $(p))
	$(PY) -c "from rabbit_policy.experiment.loop import compile_kernels; compile_kernels()"  # numba's cache
	touch $@

demo: $(STAMP)
	$(PY) scripts/demo.py

test: $(STAMP)
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadgroup

lint: $(STAMP)
	$(VENV)/bin/ruff check .

test-fast: $(STAMP)
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadgroup -m "not slow" -q

bench: $(STAMP)
	$(PY) scripts/bench_sim.py
	$(PY) scripts/bench_stack.py
	$(PY) scripts/bench_train.py

clean:
	rm -rf $(VENV) build install log .pytest_cache
