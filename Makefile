# lonlib: set-up, tests, benchmarks, JupyterLab. `make help` lists the targets.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# torch's CPU build, never a CUDA one: the local version "+cpu" is not on PyPI, so a plain
# index cannot satisfy it with gigabytes of CUDA wheels. pip finds it where it is configured
# to look (this machine's find-links), else on PyTorch's CPU index (TORCH_INDEX).
TORCH  := torch==2.13.0+cpu
TORCH_INDEX ?= https://download.pytorch.org/whl/cpu
PIP    := pip==26.3
UV     := uv==0.13.9
# The lock (docs/environment.md): exact versions with hashes, one file per install (base;
# base + dev + docs + sb3, since make test builds the site and tests the SB3 searches;
# base + docs; + lab; + bench), all
# projections of one resolution (requirements/all.txt). torch stays out of it: installed
# first, the CPU build.
REQ    := requirements
LOCK_FILES := $(foreach lock,all base dev docs lab bench,$(REQ)/$(lock).txt)
# Where uv finds torch's CPU wheel when resolving its dependencies (pip's find-links here).
TORCH_FIND_LINKS ?= $(or $(PIP_FIND_LINKS),https://download.pytorch.org/whl/cpu/torch/)
LOCK_UPGRADE ?= --upgrade
# 4 test processes on 2 cores: many tests wait on worker processes, notebook kernels and Dask
# clusters, so 4 keep both cores busy (measured: 335 s with 4, 491 s with 2 on this 2-core
# machine, the same 1604 tests passing).
TEST_JOBS ?= 4
LATEST ?= .venv-latest

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
comma := ,
BROWSER_TEST := $(if $(and $(CHROMIUM),$(shell command -v chromedriver 2>/dev/null)),yes)

.PHONY: help setup test test-browser test-latest lock bench lab lint format clean reproduce \
	figures mutants docs

help:
	@echo "make setup   create $(VENV) and install the lock $(REQ)/dev.txt + lonlib (idempotent)"
	@echo "make test    set up, then run the test suite ($(TEST_JOBS) processes; with the browser test"
	@echo "             when Chromium and chromedriver are installed: apt-get install chromium"
	@echo "             chromium-driver)"
	@echo "make test-latest  the tests in $(LATEST): the newest versions pyproject.toml allows"
	@echo "             (run it before make lock; never part of make test or CI)"
	@echo "make lock    resolve pyproject.toml's ranges again into $(REQ)/*.txt (newest versions;"
	@echo "             LOCK_UPGRADE= keeps the current pins where they still fit) and environment.yml"
	@echo "make test-browser  JupyterLab driven in headless Chromium (tests/notebooks/test_browser.py)"
	@echo "make bench   set up, then run the benchmarks (writes benchmarks/results/*.json)"
	@echo "make reproduce [CONFIG=quick|paper|file.yaml] [WORKERS=2] [SCHEDULER=tcp://host:8786]"
	@echo "             [EXECUTOR=serial|pool|dask|lockstep] [SLOTS=16] [DEVICE=cpu|cuda]"
	@echo "             sample the LON for every p, analyse it and record optima (resumes)"
	@echo "make figures [EXPERIMENT=data/reference]  every figure and table of a stored"
	@echo "             experiment again, with the paper's claims tested (never samples)"
	@echo "make lab     set up, then start JupyterLab on the project (opens at notebooks/)"
	@echo "make docs    set up, then build the documentation site into site/ (offline, --strict;"
	@echo "             tests/project/test_docs.py builds it in make test)"
	@echo "make mutants apply each result-changing mutant in tests/mutants.py; all must be killed"
	@echo "make lint    ruff check + ruff format --check + mypy (strict on [tool.mypy]'s files)"
	@echo "make clean   remove $(VENV), $(LATEST) and caches (never data/)"

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet $(PIP)

# Install a lock: every package at its locked version and hash, nothing resolved (the lock is
# complete; --no-deps also keeps stable-baselines3's torch requirement from being resolved).
# Then check that every installed package's requirements hold (a dependency added to
# pyproject.toml but not locked yet fails here: run `make lock`).
define install_lock
	$(1)/bin/python -m pip install --quiet --no-deps --require-hashes -r $(2)
endef
define install_torch
	$(1)/python -m pip install --quiet "$(TORCH)" 2>/dev/null \
	  || $(1)/python -m pip install --quiet "$(TORCH)" --extra-index-url $(TORCH_INDEX)
endef
define check_requirements
	$(1)/bin/python -m pip check >$(1)/pip-check.txt || { cat $(1)/pip-check.txt; exit 1; }
endef

# Reinstall only when the lock changes; a second `make setup` takes seconds.
$(STAMP): $(REQ)/dev.txt pyproject.toml | $(BIN)/python
	$(call install_torch,$(BIN))
	$(call install_lock,$(VENV),$(REQ)/dev.txt)
	$(BIN)/python -m pip install --quiet --no-deps -e .
	$(call check_requirements,$(VENV))
	$(BIN)/rerun analytics disable >/dev/null 2>&1 || true
	touch $(STAMP)

setup: $(STAMP)

# In TEST_JOBS processes, then the timing-sensitive tests (marker `serial`) alone.
test: setup $(if $(BROWSER_TEST),$(VENV)/.lab-installed)
	$(BIN)/python -m pytest -q -n $(TEST_JOBS) --dist worksteal -m "not serial"
	$(BIN)/python -m pytest -q -m serial

# Upstream drift, seen before it reaches a user: a fresh venv with the newest versions
# pyproject.toml allows (torch held at setup's version and build), the same tests. Not part
# of `make test` or CI.
test-latest:
	rm -rf $(LATEST)
	$(PYTHON) -m venv $(LATEST)
	$(LATEST)/bin/python -m pip install --quiet --upgrade pip
	$(call install_torch,$(LATEST)/bin)
	echo "$(TORCH)" > $(LATEST)/torch-constraint.txt
	$(LATEST)/bin/python -m pip install --quiet --upgrade --upgrade-strategy eager \
	  -c $(LATEST)/torch-constraint.txt -e ".[dev,docs,sb3$(if $(BROWSER_TEST),$(comma)lab)]"
	@$(LATEST)/bin/python $(REQ)/drift.py $(REQ)/$(if $(BROWSER_TEST),lab,dev).txt
	$(LATEST)/bin/python -m pytest -q -n $(TEST_JOBS) -p no:cacheprovider -m "not serial"
	$(LATEST)/bin/python -m pytest -q -p no:cacheprovider -m serial

UV_COMPILE = $(BIN)/uv pip compile pyproject.toml --quiet --generate-hashes \
  --python-version 3.11 --python-platform x86_64-manylinux_2_28 \
  --find-links $(TORCH_FIND_LINKS) -c $(REQ)/torch-cpu.txt --no-emit-package torch \
  --custom-compile-command "make lock"

# One resolution of every extra (all.txt), then each install's lock as its projection.
lock: setup
	$(BIN)/python -m pip install --quiet $(UV)
	$(UV_COMPILE) $(LOCK_UPGRADE) --all-extras -o $(REQ)/all.txt
	$(UV_COMPILE) -c $(REQ)/all.txt -o $(REQ)/base.txt
	$(UV_COMPILE) -c $(REQ)/all.txt --extra dev --extra docs --extra sb3 -o $(REQ)/dev.txt
	$(UV_COMPILE) -c $(REQ)/all.txt --extra docs -o $(REQ)/docs.txt
	$(UV_COMPILE) -c $(REQ)/all.txt --extra dev --extra docs --extra sb3 --extra lab -o $(REQ)/lab.txt
	$(UV_COMPILE) -c $(REQ)/all.txt --extra dev --extra docs --extra sb3 --extra bench -o $(REQ)/bench.txt
	$(BIN)/python $(REQ)/environment_yml.py $(REQ)/dev.txt $(TORCH) > environment.yml
	@! grep -iE '^(torch|triton|nvidia-)' $(LOCK_FILES) || { echo "torch/CUDA in the lock"; exit 1; }

mutants: setup
	$(BIN)/python tests/mutants.py --jobs $(or $(JOBS),2)

test-browser: $(VENV)/.lab-installed
	$(BIN)/python -m pytest -q tests/notebooks/test_browser.py

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/python -m mypy

format: setup
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

$(VENV)/.bench-installed: $(STAMP) $(REQ)/bench.txt
	$(call install_lock,$(VENV),$(REQ)/bench.txt)
	$(call check_requirements,$(VENV))
	touch $@

bench: $(VENV)/.bench-installed
	$(BIN)/python -m benchmarks

$(VENV)/.lab-installed: $(STAMP) $(REQ)/lab.txt
	$(call install_lock,$(VENV),$(REQ)/lab.txt)
	$(call check_requirements,$(VENV))
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
	echo "== verify (every stored number replayed from its stored Actor)"; \
	$(BIN)/lonlib verify $(OUT) || exit 1; \
	echo "\nDone in $$(( $$(date +%s) - start )) s. Results under $(OUT)/:"; \
	echo "  figures/      Fig. 2 boxplot, Fig. 3 3-D LON (.png, .html), Figs. 4-5 histograms,"; \
	echo "                metrics.csv (LON metrics per p), peaks.csv (peaks beside the paper's)"; \
	echo "                claims.md, claims.csv (the paper's claims tested: evidence and verdicts)"; \
	echo "                claim_d_curve.csv/.png (claim d over epsilon), power.csv (runs per claim)"; \
	echo "  recordings/   rerun .rrd files: view with  $(BIN)/rerun $(OUT)/recordings/<file>.rrd"; \
	echo "  notebooks/    the executed notebooks;  p=*/run_*/  trials and optima"

# The documentation site (MkDocs + mkdocstrings, docs/ and mkdocs.yml): offline, and --strict so
# that a broken link or reference fails (make test builds it too: tests/project/test_docs.py).
docs: setup
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

# Analysis only: figures, tables and the claims table from stored runs
# (lonlib.analysis.pipeline, the code the analyse_lon notebook runs); refuses a folder
# without an experiment.
figures: setup
	$(BIN)/lonlib analyse $(EXPERIMENT)

clean:
	rm -rf $(VENV) $(LATEST) .pytest_cache .ruff_cache build site *.egg-info
	find . -name __pycache__ -type d -not -path './data/*' -prune -exec rm -rf {} +
