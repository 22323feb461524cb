# Entry points: `make demo`, `make test` (and `make lint`). They create .venv when missing.
# `make notebooks` opens the notebooks in Jupyter Lab.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test install bench lint clean notebooks notebooks-sync aot figures

$(PY):
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) on PATH (or run: make PYTHON=python3 ...)"; exit 2; }
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev,baselines,batched,link]'
	@touch $(STAMP)

# The decision kernels of select() and select_many() compiled ahead of time (`vo3d compile`,
# vo3d_opt/formulations/aot.py), so that a first select() does not wait ~30 s for numba's JIT.
# Checked on every make (a second): rebuilt when the sources, numba, numpy or the machine
# changed (a module built from other sources is never used: select() would JIT-compile).
aot: $(STAMP)
	@$(VENV)/bin/vo3d compile --check >/dev/null 2>&1 || $(VENV)/bin/vo3d compile || echo "(not built: select() compiles its kernel with numba's JIT on first use)"

install: $(STAMP) aot

# numba's on-disk cache is keyed on each function's own file, not on the files of the functions
# it inlines: after an edit of vo3d_opt/, drop every cached kernel so nothing stale is loaded.
NUMBA_STAMP := $(VENV)/.numba-sources
$(NUMBA_STAMP): $(shell find vo3d_opt -name '*.py') | $(PY)
	@find vo3d_opt -name '*.nb[ic]' -delete
	@touch $@

demo: $(STAMP) $(NUMBA_STAMP) aot
	$(PY) -m vo3d_opt.demo

test: $(STAMP) $(NUMBA_STAMP) aot
	$(PY) -m pytest -q -p no:cacheprovider -n 2

# ruff (lint + format check), mypy and the import layers (import-linter), configured in
# pyproject.toml. The notebooks' .py
# sources are linted too (their .ipynb twins are excluded in pyproject.toml).
lint: $(STAMP)
	$(VENV)/bin/ruff check vo3d_opt setup.py notebooks
	$(VENV)/bin/ruff format --check vo3d_opt setup.py notebooks
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

# Jupyter Lab on the notebooks. Each is a pair, NN_name.py (the source) and NN_name.ipynb;
# jupytext first brings the older file of each pair up to date, and Jupyter saves both.
JUPYTER_ARGS ?=
notebooks: $(STAMP)
	$(VENV)/bin/jupytext --sync notebooks/[0-9]*.py
	$(VENV)/bin/jupyter lab $(JUPYTER_ARGS) notebooks

# Each NN_name.ipynb rewritten from its NN_name.py and cleared of outputs: what is committed.
notebooks-sync: $(STAMP)
	$(VENV)/bin/jupytext --update --to ipynb notebooks/[0-9]*.py
	$(VENV)/bin/jupyter nbconvert --log-level WARN --clear-output --inplace notebooks/[0-9]*.ipynb

bench: $(STAMP) $(NUMBA_STAMP) aot
	$(PY) benchmarks/bench_select.py

# The PNGs of docs/figures.md (cases 1, 2, 4, random-crossing-1000 and a replay frame).
figures: $(STAMP) $(NUMBA_STAMP) aot
	$(PY) benchmarks/figures.py

clean:
	rm -rf $(VENV) out vo3d_opt/formulations/_kernel_aot*
	find vo3d_opt -name '*.nb[ic]' -delete
