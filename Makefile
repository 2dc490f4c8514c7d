# lonlib: set-up, tests, benchmarks, JupyterLab. `make help` lists the targets.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
TORCH  := torch==2.13.0

.PHONY: help setup test bench lab lint format clean

help:
	@echo "make setup   create $(VENV) and install lonlib with its dev extra (idempotent)"
	@echo "make test    set up, then run the test suite"
	@echo "make bench   set up, then run the benchmarks (writes benchmarks/results/*.json)"
	@echo "make lab     set up, then start JupyterLab in the project's environment"
	@echo "make lint    ruff check + ruff format --check"
	@echo "make clean   remove $(VENV) and caches (never data/)"

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# Reinstall only when the dependency list changes; a second `make setup` takes seconds.
$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet $(TORCH)
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	$(BIN)/rerun analytics disable >/dev/null 2>&1 || true
	touch $(STAMP)

setup: $(STAMP)

test: setup
	$(BIN)/python -m pytest -q

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: setup
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

$(VENV)/.bench-installed: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[dev,bench]"
	touch $@

bench: $(VENV)/.bench-installed
	$(BIN)/python -m benchmarks

$(VENV)/.lab-installed: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[dev,lab]"
	touch $@

lab: $(VENV)/.lab-installed
	$(BIN)/jupyter lab --no-browser $$( [ "$$(id -u)" = 0 ] && echo --allow-root ) notebooks

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache build *.egg-info
	find . -name __pycache__ -type d -not -path './data/*' -prune -exec rm -rf {} +
