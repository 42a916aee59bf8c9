# Two commands for a fresh machine: `make demo` and `make test`. Each creates the virtual
# environment and installs what it needs by itself.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test install benchmark-shapes benchmark-tunnel benchmark-speed clean

$(STAMP): setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[ros,dev]'
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q test

# The demo: a 40 s featureless stretch of tunnel Trial 1 (simulated once, then cached in
# data/sim), odometry with LiLi and without degeneracy handling, ATE/RPE table and plots.
demo: $(STAMP)
	$(PY) -m lili_odom.cli evaluate --trials 1 --methods none lili --resolution 32x256 \
		--start 70 --duration 40 --out demo_output

benchmark-shapes: $(STAMP)
	$(PY) benchmarks/shapes.py

benchmark-tunnel: $(STAMP)
	$(PY) benchmarks/tunnel.py

benchmark-speed: $(STAMP)
	$(PY) benchmarks/speed.py

clean:
	rm -rf $(VENV) build install log *.egg-info
