# Two commands: `make run` and `make test`. Both create .venv from this project's own files first.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
CAMPAIGN ?= scenarios/campaign_default.yaml

.PHONY: setup run test lint bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

setup: $(STAMP)

run: $(STAMP)
	$(VENV)/bin/trafficsim campaign $(CAMPAIGN) --out out/$(basename $(notdir $(CAMPAIGN)))

test: $(STAMP)
	$(PY) -m ruff check trafficsim tests
	$(PY) -m pytest -n auto --benchmark-disable

lint: $(STAMP)
	$(PY) -m ruff check trafficsim tests

bench: $(STAMP)
	mkdir -p out
	$(PY) -m pytest tests/benchmarks --benchmark-only --benchmark-timer=time.process_time \
		--benchmark-json=out/benchmark.json

clean:
	rm -rf $(VENV) out build *.egg-info
