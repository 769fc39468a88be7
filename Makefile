# The two commands the README opens with: `make demo` and `make test`.
# Both create .venv when missing and install into it at the exact versions of constraints.txt (the
# published numbers): `make demo` corl's core alone (what the door needs; no extras), `make test`
# every extra the suite tests. pyproject.toml declares ranges; `make test-lowest` and `make
# test-latest` run the whole suite at the lowest and at the newest versions they allow, and `make
# test-wheel` runs the built wheel as a user installs it.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
CORE_STAMP := $(VENV)/.core-installed
STAMP := $(VENV)/.installed
EXTRAS := test,ray,dask,docs,serve
# One BLAS thread: small banded and dense factorizations are far slower with two.
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1

.PHONY: demo test test-fast test-lowest test-latest test-wheel dist constraints bench synthetic docs clean

$(PY):
	@echo "==> creating $(VENV) ($(PYTHON) -m venv) and upgrading its pip"
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

# The core: numpy, scipy, cma, joblib, typer, rich, matplotlib, mujoco, example-robot-data, imageio.
$(CORE_STAMP): pyproject.toml constraints.txt | $(PY)
	@echo "==> installing corl's core into $(VENV) at the versions of constraints.txt (no extras: no ray, dask, torch, docs)"
	$(PY) -m pip install --progress-bar on -c constraints.txt -e .
	touch $(CORE_STAMP)

$(STAMP): pyproject.toml constraints.txt | $(PY)
	@echo "==> installing corl with the extras the suite tests ($(EXTRAS)) into $(VENV) at the versions of constraints.txt"
	$(PY) -m pip install --quiet -c constraints.txt -e ".[$(EXTRAS)]"
	touch $(STAMP) $(CORE_STAMP)

demo: $(CORE_STAMP)
	@echo "==> learning to open the door: corl run door --seed 0 --video (a few minutes; results/door/)"
	$(VENV)/bin/corl run door --seed 0 --out results/door --video

# The browser test of `corl report`'s page needs a headless Chromium: installed system-wide with apt-get
# when missing and when run as root (CI), said before it is done.
test: $(STAMP)
	@if ! command -v chromium >/dev/null && [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "==> installing Chromium system-wide (apt-get install chromium, as root): the browser test of corl report's page needs it"; \
		(apt-get update -qq && apt-get install -y -qq chromium >/dev/null) || echo "could not install chromium"; fi
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

# The release as a user gets it (CI runs it after `make test`): tools/test_wheel.py builds the sdist
# and the wheel, checks their files, installs the wheel at the locked versions into a fresh venv
# outside the checkout and runs `corl --help`, the door with its video (no MUJOCO_GL, no display),
# `corl status` against summary.json and a test of the MuJoCo kit from it.
test-wheel: $(STAMP)
	$(PY) tools/test_wheel.py

# The sdist and the wheel in dist/, their files checked (tools/check_dist.py).
dist: $(STAMP)
	rm -rf dist
	$(PY) -m build --outdir dist .
	$(PY) tools/check_dist.py dist

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
	rm -rf $(VENV) $(LOWEST) $(LATEST) results build dist site *.egg-info src/*.egg-info
