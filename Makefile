# The two commands the README opens with: `make demo` and `make test`.
# Each creates .venv from scratch when missing and installs what it needs, at the exact versions
# of constraints.txt (the published numbers). pyproject.toml declares ranges; `make test-lowest` and
# `make test-latest` run the whole suite at the lowest and at the newest versions they allow.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# One BLAS thread: small banded and dense factorizations are far slower with two.
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1

.PHONY: demo test test-fast test-lowest test-latest constraints bench synthetic docs clean

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c constraints.txt -e ".[test,ray,dask,docs,serve]"
	touch $(STAMP)

demo: $(STAMP)
	MUJOCO_GL=egl $(VENV)/bin/corl run door --seed 0 --out results/door --video

# `make test` installs headless Chromium for the browser test of `corl report` (when root with apt-get).
test: $(STAMP)
	@command -v chromium >/dev/null || [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null || \
		(apt-get update -qq && apt-get install -y -qq chromium >/dev/null) || echo "could not install chromium"
	$(PY) -m pytest -q

test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not slow"

# Both ends of every range pyproject.toml declares (CI runs both after `make test`), the whole suite
# each time, slow tests included: the lowest versions (constraints-lowest.txt, pinned) and the newest
# ones pip resolves today (no constraints, resolved afresh on every run, printed in the log).
LOWEST := .venv-lowest
LOWEST_STAMP := $(LOWEST)/.installed
$(LOWEST_STAMP): pyproject.toml constraints-lowest.txt
	rm -rf $(LOWEST)
	$(PYTHON) -m venv $(LOWEST)
	$(LOWEST)/bin/python -m pip install --quiet --upgrade pip
	$(LOWEST)/bin/python -m pip install --quiet -c constraints-lowest.txt -e ".[test,serve,docs]"
	touch $(LOWEST_STAMP)

VERSIONS := import corl.versions as v; print(' '.join(f'{k} {x}' for k, x in v.library_versions().items()))

test-lowest: $(LOWEST_STAMP)
	@echo "lowest versions:"; $(LOWEST)/bin/python -c "$(VERSIONS)"
	$(LOWEST)/bin/python -m pytest -q -p no:cacheprovider

# Always a fresh venv: "newest" means what pip resolves now, not what it resolved last time.
LATEST := .venv-latest
test-latest:
	rm -rf $(LATEST)
	$(PYTHON) -m venv $(LATEST)
	$(LATEST)/bin/python -m pip install --quiet --upgrade pip
	$(LATEST)/bin/python -m pip install --quiet --upgrade --upgrade-strategy eager -e ".[test,serve,docs]"
	@echo "newest versions:"; $(LATEST)/bin/python -c "$(VERSIONS)"
	$(LATEST)/bin/python -m pytest -q -p no:cacheprovider

# Regenerate constraints.txt from .venv (after upgrading on purpose; the published numbers move with it).
constraints: $(STAMP)
	$(PY) .ci/freeze_constraints.py > constraints.txt

synthetic: $(STAMP)
	$(VENV)/bin/corl bench synthetic --starts 100 --seed 0 --out results/synthetic

bench: $(STAMP)
	$(PY) benchmarks/pibu_speed.py

# The documentation site (mkdocs.yml, docs/): the guide, the reproduction and the API reference
# from the docstrings, built offline into site/ with warnings as errors (open site/index.html).
DOCS_STAMP := $(VENV)/.docs-installed
$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(PY) -m pip install --quiet -c constraints.txt -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict --site-dir site

clean:
	rm -rf $(VENV) $(LOWEST) $(LATEST) results build site *.egg-info src/*.egg-info
