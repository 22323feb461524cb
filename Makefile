# Entry points: `make demo`, `make test` (and `make lint`). They create .venv when missing.
# `make notebooks` opens the notebooks in Jupyter Lab, `make notebooks-run` executes them outside it;
# `make docs` builds the documentation site.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
# What each target installs (pyproject.toml's extras): the demo only [sim] (the simulator, the
# figures, Parquet); make install, test, lint and the rest every extra and [dev], since the
# suite exercises them all; make notebooks Jupyter Lab on top.
STAMP := $(VENV)/.installed
SIM_STAMP := $(VENV)/.installed-sim
NOTEBOOKS_STAMP := $(VENV)/.installed-notebooks
BUILD_STAMP := $(VENV)/.build-requirements
CORE_STAMP := $(VENV)/.core

.PHONY: demo test install bench lint clean notebooks notebooks-sync notebooks-run figures docs

$(PY):
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) on PATH (or run: make PYTHON=python3 ...)"; exit 2; }
	$(PYTHON) -m venv $(VENV)

# The build requirements first (pyproject.toml's build-system.requires; cmake and ninja from
# PyPI only where the machine has none), then the package, editable and built without
# isolation, so that its persistent build directory (build/) stays valid between rebuilds.
BUILD_REQS := 'scikit-build-core>=0.10' 'nanobind>=2.4' 'numpy>=1.26'
$(BUILD_STAMP): | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet $(BUILD_REQS)
	@command -v cmake >/dev/null 2>&1 || $(PY) -m pip install --quiet 'cmake>=3.18'
	@command -v ninja >/dev/null 2>&1 || $(PY) -m pip install --quiet ninja
	@touch $@

$(SIM_STAMP): pyproject.toml | $(BUILD_STAMP)
	$(PY) -m pip install --quiet --no-build-isolation -e '.[sim]'
	@touch $(SIM_STAMP) $(CORE_STAMP)

$(STAMP): pyproject.toml | $(BUILD_STAMP)
	$(PY) -m pip install --quiet --no-build-isolation -e '.[all,dev,docs]'
	@touch $(STAMP) $(SIM_STAMP) $(CORE_STAMP)

$(NOTEBOOKS_STAMP): pyproject.toml | $(STAMP)
	$(PY) -m pip install --quiet --no-build-isolation -e '.[all,dev,docs,notebooks]'
	@touch $@ $(CORE_STAMP)

# The compiled core (vo3d_opt/algorithm/, CMakeLists.txt), rebuilt when a source changes:
# incremental, in the same build directory.
$(CORE_STAMP): $(wildcard vo3d_opt/algorithm/*.hpp vo3d_opt/algorithm/*.cpp) CMakeLists.txt | $(SIM_STAMP)
	$(PY) -m pip install --quiet --no-build-isolation --no-deps -e .
	@touch $@

install: $(STAMP) $(CORE_STAMP)

demo: $(SIM_STAMP) $(CORE_STAMP)
	$(PY) -m vo3d_opt.demo

# PYTEST_ARGS passes options on (e.g. make test PYTEST_ARGS=--durations=20)
PYTEST_ARGS ?=
test: $(STAMP) $(CORE_STAMP)
	$(PY) -m pytest -q -p no:cacheprovider -n 2 $(PYTEST_ARGS)

# ruff (lint + format check), mypy and the import layers (import-linter), configured in
# pyproject.toml. The notebooks' .py
# sources are linted too (their .ipynb twins are excluded in pyproject.toml).
lint: $(STAMP)
	$(VENV)/bin/ruff check vo3d_opt notebooks
	$(VENV)/bin/ruff format --check vo3d_opt notebooks
	$(VENV)/bin/mypy
	$(VENV)/bin/lint-imports

# Jupyter Lab on the notebooks. Each is a pair, NN_name.py (the source) and NN_name.ipynb;
# jupytext first brings the older file of each pair up to date, and Jupyter saves both.
JUPYTER_ARGS ?=
notebooks: $(NOTEBOOKS_STAMP)
	$(VENV)/bin/jupytext --sync notebooks/[0-9]*.py
	$(VENV)/bin/jupyter lab $(JUPYTER_ARGS) notebooks

# Each NN_name.ipynb rewritten from its NN_name.py and cleared of outputs: what is committed.
notebooks-sync: $(NOTEBOOKS_STAMP)
	$(VENV)/bin/jupytext --update --to ipynb notebooks/[0-9]*.py
	$(VENV)/bin/jupyter nbconvert --log-level WARN --clear-output --inplace notebooks/[0-9]*.ipynb

# Every notebook executed outside Jupyter Lab (nbconvert, the venv's own kernel), top to bottom;
# the executed copies go to out/notebooks/, the committed .ipynb stay without outputs.
notebooks-run: $(STAMP) $(CORE_STAMP)
	$(VENV)/bin/jupyter nbconvert --log-level WARN --to notebook --execute \
		--ExecutePreprocessor.timeout=600 --output-dir out/notebooks notebooks/[0-9]*.ipynb

# The documentation site (mkdocs.yml, docs/) into site/, strictly: a broken link, a page missing
# from the navigation or a renamed function in the API pages fails it (tests/test_docs.py too).
docs: $(STAMP) $(CORE_STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir site

bench: $(STAMP) $(CORE_STAMP)
	$(PY) benchmarks/bench_select.py

# The PNGs of docs/figures.md (cases 1, 2, 4, random-crossing-1000 and a replay frame).
figures: $(STAMP) $(CORE_STAMP)
	$(PY) benchmarks/figures.py

clean:
	rm -rf $(VENV) out build site
