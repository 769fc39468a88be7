# The two commands the README opens with: `make demo` and `make test`.
# Each creates .venv from scratch when missing and installs what it needs, at the exact versions
# of constraints.txt (the published numbers). pyproject.toml declares ranges; `make test-lowest`
# installs the lowest of them (constraints-lowest.txt) in .venv-lowest and runs the fast tests.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# One BLAS thread: small banded and dense factorizations are far slower with two.
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1

.PHONY: demo test test-fast test-lowest constraints bench synthetic docs clean

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e ".[test,ray,dask,docs]"
	touch $(STAMP)

demo: $(STAMP)
	MUJOCO_GL=egl $(VENV)/bin/corl run door --seed 0 --out results/door

# `make test` installs headless Chromium for the browser test of `corl report` (when root with apt-get).
test: $(STAMP)
	@command -v chromium >/dev/null || [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null || \
		(apt-get update -qq && apt-get install -y -qq chromium >/dev/null) || echo "could not install chromium"
	$(PY) -m pytest -q

test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not slow"

# The lowest declared versions (CI runs it after `make test`): the fast tests only.
LOWEST := .venv-lowest
LOWEST_STAMP := $(LOWEST)/.installed
$(LOWEST_STAMP): pyproject.toml constraints-lowest.txt
	rm -rf $(LOWEST)
	$(PYTHON) -m venv $(LOWEST)
	$(LOWEST)/bin/python -m pip install --quiet --upgrade pip
	$(LOWEST)/bin/python -m pip install --quiet -c constraints-lowest.txt -e ".[test]"
	touch $(LOWEST_STAMP)

test-lowest: $(LOWEST_STAMP)
	$(LOWEST)/bin/python -c "import numpy, scipy, mujoco; print('lowest: numpy', numpy.__version__, 'scipy', scipy.__version__, 'mujoco', mujoco.__version__)"
	$(LOWEST)/bin/python -m pytest -q -m "not slow" -p no:cacheprovider

# Regenerate constraints.txt from .venv (after upgrading on purpose; the published numbers move with it).
constraints: $(STAMP)
	$(PY) .ci/freeze_constraints.py > constraints.txt

synthetic: $(STAMP)
	$(VENV)/bin/corl bench synthetic --starts 100 --seed 0 --out results/synthetic

bench: $(STAMP)
	$(PY) benchmarks/pibu_speed.py

# API reference from the docstrings: one HTML page per module in docs/api (see docs/index.md).
DOCS_STAMP := $(VENV)/.docs-installed
$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(PY) -m pip install --quiet -c constraints.txt -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	rm -rf docs/api
	$(PY) docs/build_api.py docs/api

clean:
	rm -rf $(VENV) $(LOWEST) results build docs/api *.egg-info src/*.egg-info
