# dexroll: `make run` starts the planning service, `make test` runs the whole suite.
# Both create .venv from nothing when it is missing. The Dockerfile runs the same targets.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
PIP := $(BIN)/python -m pip --disable-pip-version-check
DEPS := $(VENV)/.deps
INSTALLED := $(VENV)/.installed
DEV := $(VENV)/.dev

.PHONY: deps install run demo openapi test test-slow lint bench bench-quick viewer-vendor clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

# third-party runtime dependencies only (their own Docker layer)
$(DEPS): pyproject.toml clients/python/pyproject.toml tools/requirements.py | $(BIN)/python
	$(PIP) install --quiet --upgrade pip
	$(BIN)/python tools/requirements.py > $(VENV)/requirements.txt
	$(PIP) install --quiet -r $(VENV)/requirements.txt
	touch $@

# the two packages themselves: the service (dexroll) and the client with the wire models
$(INSTALLED): $(DEPS)
	$(PIP) install --quiet --no-deps -e ./clients/python -e .
	touch $@

$(DEV): $(INSTALLED)
	$(PIP) install --quiet -e '.[dev]'
	touch $@

deps: $(DEPS)

install: $(INSTALLED)

run: $(INSTALLED)
	$(BIN)/dexroll serve

demo: $(INSTALLED)
	$(BIN)/dexroll demo examples

openapi: $(INSTALLED)
	$(BIN)/dexroll openapi > openapi.json

# the plan viewer's browser tests (tests/test_view_browser.py) drive Debian's headless
# Chromium (through Playwright, never `playwright install`): installed here when missing
CHROMIUM := /usr/bin/chromium
$(CHROMIUM):
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing Debian's chromium for the viewer's browser tests"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; \
	else \
	    echo "make: $(CHROMIUM) is missing and this is not root: run" \
	         "'sudo apt-get install -y chromium' (Debian) for the viewer's browser tests;" \
	         "they are skipped without it" >&2; \
	fi

# the default run leaves out the tests marked `slow` (long gaits planned and executed in
# MuJoCo, 35-95 s each): `make test-slow` runs them
test: $(DEV) | $(CHROMIUM)
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/python -m pytest -q -n 2 --dist loadfile -m "not slow"

test-slow: $(DEV)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile -m slow

lint: $(DEV)
	$(BIN)/ruff check .
	$(BIN)/mypy

# one BLAS thread, as the service's workers and the bench runners use (docs/performance.md)
bench: $(INSTALLED)
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python benchmarks/ball_on_palm.py

# the quick benchmark suite (docs/benchmarks.md): report in bench-results/quick-<time>/
bench-quick: $(DEV)
	$(BIN)/dexroll bench quick

# rebuild the viewer's bundled three.js (planner_service/view/static/three.min.js, committed)
# from the npm registry: the versions pinned in planner_service/view/js/package.json
viewer-vendor:
	cd planner_service/view/js && npm install --no-audit --no-fund && npm run build
	cp planner_service/view/js/node_modules/three/LICENSE planner_service/view/static/three.LICENSE

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
