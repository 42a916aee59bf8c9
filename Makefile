# Two commands for a fresh machine: `make demo` and `make test`. Each creates the virtual
# environment and installs what it needs by itself.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test install benchmark-shapes clean

$(STAMP): setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[ros,dev]'
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q test

demo: $(STAMP)
	$(PY) benchmarks/shapes.py

benchmark-shapes: $(STAMP)
	$(PY) benchmarks/shapes.py

clean:
	rm -rf $(VENV) build install log *.egg-info
