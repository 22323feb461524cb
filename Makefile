# Entry points: `make demo`, `make test` (and `make lint`). They create .venv when missing.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test install bench lint clean

$(PY):
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) on PATH (or run: make PYTHON=python3 ...)"; exit 2; }
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev,baselines]'
	@touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(PY) -m vo3d_opt.demo

test: $(STAMP)
	$(PY) -m pytest -q -p no:cacheprovider -n 2

# ruff (lint + format check) and mypy, configured in pyproject.toml.
lint: $(STAMP)
	$(VENV)/bin/ruff check vo3d_opt setup.py
	$(VENV)/bin/ruff format --check vo3d_opt setup.py
	$(VENV)/bin/mypy

bench: $(STAMP)
	$(PY) benchmarks/bench_select.py

clean:
	rm -rf $(VENV) out
