# Two commands for a fresh machine: `make demo` and `make test`. Each creates the virtual
# environment and installs what it needs by itself.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test install install-ouster benchmark-shapes benchmark-tunnel benchmark-speed \
	benchmark-detection-cost benchmark-robustness clean

$(STAMP): setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[ros,dev]'
	touch $(STAMP)

install: $(STAMP)

# The Ouster SDK for reading .pcap/.osf recordings (see setup.py's `ouster` extra for why
# --no-deps).
install-ouster: $(STAMP)
	$(PY) -m pip install --quiet -e '.[ouster]'
	$(PY) -m pip install --quiet --no-deps ouster-sdk==1.0.1

test: $(STAMP)
	$(PY) -m pytest -q test

# The demo: a 40 s featureless stretch of tunnel Trial 1 (simulated once, then cached in
# data/sim), odometry with LiLi and without degeneracy handling, ATE/RPE table and plots.
demo: $(STAMP)
	$(PY) -m lili_odom.cli evaluate --trials 1 --methods none lili --resolution 32x256 \
		--start 70 --duration 40 --out demo_output

benchmark-shapes: $(STAMP)
	$(PY) benchmarks/shapes.py

# Table II: Trials 1 and 2, every method, OS1 at 64 x 512 (bags ~6 GB in data/sim, ~1.5 h on
# 2 cores); `python benchmarks/tunnel.py --resolution 128x1024` for the full sensor (~22 GB).
benchmark-tunnel: $(STAMP)
	$(PY) benchmarks/tunnel.py --resolution 64x512 --jobs 2

benchmark-speed: $(STAMP)
	$(PY) benchmarks/speed.py

benchmark-detection-cost: $(STAMP)
	$(PY) benchmarks/detection_cost.py

benchmark-robustness: $(STAMP)
	$(PY) benchmarks/faults.py --resolution 32x256 --play-rates
	$(PY) benchmarks/long_run.py

clean:
	rm -rf $(VENV) build install log *.egg-info
