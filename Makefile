# Two commands for a fresh machine: `make demo` and `make test`. Each creates the virtual
# environment and installs what it needs by itself. Benchmarks run from the repository root as
# modules (`python -m benchmarks.NAME`) and write benchmarks/results/.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test install install-ouster benchmark-shapes benchmark-tunnel benchmark-speed \
	benchmark-detection-cost benchmark-robustness benchmark-suite benchmark-fuzz clean

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
	$(PY) -m benchmarks.shapes

# Table II: Trials 1 and 2, every method, OS1 at 64 x 512 (bags ~6 GB in data/sim, ~1.5 h on
# 2 cores); `python -m benchmarks.tunnel --resolution 128x1024` for the full sensor (~22 GB).
benchmark-tunnel: $(STAMP)
	$(PY) -m benchmarks.tunnel --resolution 64x512 --jobs 2

benchmark-speed: $(STAMP)
	$(PY) -m benchmarks.speed

benchmark-detection-cost: $(STAMP)
	$(PY) -m benchmarks.detection_cost

benchmark-robustness: $(STAMP)
	$(PY) -m benchmarks.faults --resolution 32x256 --play-rates
	$(PY) -m benchmarks.long_run

# The scenario suite: every scenario (each one's own sensor and window), our methods and the
# peers (KISS-ICP, GenZ-ICP, RKO-LIO, wheels), every seed, into benchmarks/results/suite.
# Bags are simulated once into the simulator cache. About 2.5 hours on 2 cores; --resume
# continues an interrupted run.
benchmark-suite: $(STAMP)
	$(PY) -m pip install --quiet -e '.[peers]'
	$(PY) -m lili_odom.cli suite --preset full --jobs 2 --resume --out benchmarks/results/suite

# Are the suite's rows the same on `--backend local` and `--backend ray` (a local Ray instance)?
# CI pieces of two scenarios, deterministic configuration; see docs/cluster.md.
.PHONY: benchmark-suite-backends
benchmark-suite-backends: $(STAMP)
	$(PY) -m pip install --quiet -e '.[cluster]'
	$(PY) benchmarks/suite_backends.py --out benchmarks/results/suite_backends

# Fuzz campaign over every input door (10,374 seeded cases run in worker subprocesses; about
# 20-40 min on 2 cores): benchmarks/results/fuzz.md, fuzz.json and reproducers of any finding.
benchmark-fuzz: $(STAMP)
	nice -n 10 $(PY) -m benchmarks.fuzz

clean:
	rm -rf $(VENV) build install log *.egg-info
