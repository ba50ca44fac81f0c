# motionx — every command creates/updates its own virtual environment.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: venv test bench demo clean reliability stack

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(STAMP)

venv: $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q $(PYTEST_ARGS)

demo: $(STAMP)
	$(VENV)/bin/motionx demo --out out/demo

bench: $(STAMP)
	$(PY) -m bench.run --out bench/results.json

reliability: $(STAMP)
	MOTIONX_RELIABILITY_REPEAT=$${MOTIONX_RELIABILITY_REPEAT:-20} $(PY) -m pytest -q tests/service -k reliability

stack: $(STAMP)
	$(VENV)/bin/motionx stack --workers $${WORKERS:-2}

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
