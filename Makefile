# The two commands the README opens with: `make demo` and `make test`.
# Each creates .venv from scratch when missing and installs what it needs.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# One BLAS thread: small banded and dense factorizations are far slower with two.
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1

.PHONY: demo test test-fast bench synthetic clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	MUJOCO_GL=egl $(VENV)/bin/corl run door --seed 0 --out results/door

test: $(STAMP)
	$(PY) -m pytest -q

test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not slow"

synthetic: $(STAMP)
	$(VENV)/bin/corl bench synthetic --starts 100 --seed 0 --out results/synthetic

bench: $(STAMP)
	$(PY) benchmarks/pibu_speed.py

clean:
	rm -rf $(VENV) results build *.egg-info src/*.egg-info
