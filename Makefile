# lonlib: set-up, tests, benchmarks, JupyterLab. `make help` lists the targets.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
TORCH  := torch==2.13.0

CONFIG    ?= quick
WORKERS   ?= 2
SCHEDULER ?=
EXECUTOR  ?=
SLOTS     ?=
DEVICE    ?=
OUT       ?= data/$(basename $(notdir $(CONFIG)))
EXPERIMENT ?= data/reference
# papermill with an encrypted kernel connection and the kernel's stderr (progress) shown here
PAPERMILL := $(BIN)/python -m lonlib.notebook_run --log-level WARNING --no-progress-bar
# The browser test runs in `make test` when Chromium and chromedriver are installed.
CHROMIUM  := $(shell for b in chromium chromium-browser google-chrome; do command -v $$b && break; done)
BROWSER_TEST := $(if $(and $(CHROMIUM),$(shell command -v chromedriver 2>/dev/null)),yes)

.PHONY: help setup test test-browser bench lab lint format clean reproduce figures mutants

help:
	@echo "make setup   create $(VENV) and install lonlib with its dev extra (idempotent)"
	@echo "make test    set up, then run the test suite (with the browser test when Chromium"
	@echo "             and chromedriver are installed: apt-get install chromium chromium-driver)"
	@echo "make test-browser  JupyterLab driven in headless Chromium (tests/test_browser.py)"
	@echo "make bench   set up, then run the benchmarks (writes benchmarks/results/*.json)"
	@echo "make reproduce [CONFIG=quick|paper|file.yaml] [WORKERS=2] [SCHEDULER=tcp://host:8786]"
	@echo "             [EXECUTOR=serial|pool|dask|lockstep] [SLOTS=16] [DEVICE=cpu|cuda]"
	@echo "             sample the LON for every p, analyse it and record optima (resumes)"
	@echo "make figures [EXPERIMENT=data/reference]  every figure and table of a stored"
	@echo "             experiment again, with the paper's claims tested (never samples)"
	@echo "make lab     set up, then start JupyterLab on the project (opens at notebooks/)"
	@echo "make mutants apply each result-changing mutant in tests/mutants.py; all must be killed"
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

test: setup $(if $(BROWSER_TEST),$(VENV)/.lab-installed)
	$(BIN)/python -m pytest -q

mutants: setup
	$(BIN)/python tests/mutants.py --jobs $(or $(JOBS),2)

test-browser: $(VENV)/.lab-installed
	$(BIN)/python -m pytest -q tests/test_browser.py

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

# The whole project in the file browser (data/ beside notebooks/), opened at notebooks/.
lab: $(VENV)/.lab-installed
	$(BIN)/jupyter lab --no-browser $$( [ "$$(id -u)" = 0 ] && echo --allow-root ) \
	  --ServerApp.root_dir=. --LabApp.default_url=/lab/tree/notebooks \
	  --MappingKernelManager.transport_encryption=auto

# Sampling, analysis and recordings through the notebooks (executed copies are kept).
reproduce: setup
	@mkdir -p $(OUT)/notebooks
	@start=$$(date +%s); \
	echo "== sampling every p of $(CONFIG) (executor $(or $(EXECUTOR),auto), $(WORKERS) workers$(if $(SCHEDULER), on $(SCHEDULER))$(if $(SLOTS), $(SLOTS) slots)$(if $(DEVICE), on $(DEVICE)))"; \
	$(PAPERMILL) notebooks/sample_lon.ipynb $(OUT)/notebooks/sample_lon.ipynb \
	  -r config "$(CONFIG)" -p p 0 -p workers $(WORKERS) -r scheduler "$(SCHEDULER)" \
	  -r executor "$(EXECUTOR)" -p slots $(or $(SLOTS),0) -r device "$(DEVICE)" \
	  -r out "$(OUT)" || exit 1; \
	echo "== analysis"; \
	$(PAPERMILL) notebooks/analyse_lon.ipynb $(OUT)/notebooks/analyse_lon.ipynb \
	  -r experiment_dir "$(OUT)" || exit 1; \
	echo "== recordings"; \
	$(PAPERMILL) notebooks/record_optima.ipynb $(OUT)/notebooks/record_optima.ipynb \
	  -r experiment_dir "$(OUT)" -p show_inline_viewer False || exit 1; \
	$(BIN)/lonlib status $(OUT); \
	echo "\nDone in $$(( $$(date +%s) - start )) s. Results under $(OUT)/:"; \
	echo "  figures/      Fig. 2 boxplot, Fig. 3 3-D LON (.png, .html), Figs. 4-5 histograms,"; \
	echo "                metrics.csv (LON metrics per p), peaks.csv (peaks beside the paper's)"; \
	echo "                claims.md, claims.csv (the paper's claims tested: evidence and verdicts)"; \
	echo "  recordings/   rerun .rrd files: view with  $(BIN)/rerun $(OUT)/recordings/<file>.rrd"; \
	echo "  notebooks/    the executed notebooks;  p=*/run_*/  trials and optima"

# Analysis only: figures, tables and the claims table from stored runs (lonlib.analysis, the
# code the analyse_lon notebook runs); refuses a folder without an experiment.
figures: setup
	$(BIN)/lonlib analyse $(EXPERIMENT)

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache build *.egg-info
	find . -name __pycache__ -type d -not -path './data/*' -prune -exec rm -rf {} +
