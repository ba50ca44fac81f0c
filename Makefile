# motionx — every command creates/updates its own virtual environment.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
RUNTIME_STAMP := $(VENV)/.installed-runtime
WEB    := service/web
WEB_STAMP := $(WEB)/node_modules/.installed

.PHONY: venv test lint bench demo clean reliability stack fuzz

# the test extras (pytest, schemathesis, playwright, ruff, mypy, ...) for make test, lint, bench
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(STAMP) $(RUNTIME_STAMP)

# the runtime only, for make demo and make stack (the test extras' venv has it too)
$(RUNTIME_STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e .
	touch $(RUNTIME_STAMP)

# three.js for the web page (served locally by the API); skipped with a note when npm is missing
$(WEB_STAMP): $(WEB)/package.json $(WEB)/package-lock.json
	@if command -v npm >/dev/null 2>&1; then \
	  cd $(WEB) && npm ci --no-audit --no-fund --ignore-scripts --loglevel=error && touch node_modules/.installed; \
	else echo "npm not found: the web page's 3D preview is disabled (install Node.js and npm)"; fi

venv: $(STAMP) $(WEB_STAMP)

# static checks: ruff (rules in pyproject.toml) on everything, mypy on solver/ and mjcf/
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy

# the tests in parallel, one process per core (at most 4), each test file in one process (its module
# fixtures are computed once); PYTEST_PARALLEL= runs them in this process
PYTEST_PARALLEL ?= -n auto --maxprocesses 4 --dist loadfile
test: $(STAMP) $(WEB_STAMP) lint
	$(PY) -m pytest -q $(PYTEST_PARALLEL) $(PYTEST_ARGS)

demo: $(RUNTIME_STAMP) $(WEB_STAMP)
	$(VENV)/bin/motionx demo --out out/demo

bench: $(STAMP)
	$(PY) -m bench.run --out bench/results.json

reliability: $(STAMP)
	MOTIONX_RELIABILITY_REPEAT=$${MOTIONX_RELIABILITY_REPEAT:-20} $(PY) -m pytest -q tests/service -k reliability

# schemathesis' command line, every phase and check, >= FUZZ_CASES cases on SQLite then PostgreSQL; no 5xx
fuzz: $(STAMP) $(WEB_STAMP)
	$(PY) tests/service/fuzz.py --cases $${FUZZ_CASES:-10000}

stack: $(RUNTIME_STAMP) $(WEB_STAMP)
	$(VENV)/bin/motionx stack --workers $${WORKERS:-2}

clean:
	rm -rf $(VENV) $(WEB)/node_modules .pytest_cache .hypothesis
