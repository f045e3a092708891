# Every target sets up the environment first (quick when nothing changed).
# Stage targets take EXPERIMENT=smoke|default|paper and ARGS="<more Hydra overrides>".
SHELL := /bin/bash
.DEFAULT_GOAL := help
PY := .venv/bin/python
EXPERIMENT ?= default
ARGS ?=
STAGE ?= generate
NPROC ?= 1
# Test workers (pytest-xdist): one per core, at most 4; each takes whole test files (TEST_WORKERS=0: one process).
TEST_WORKERS ?= auto
# Tests keep Python's compiled bytecode (__pycache__, ignored by git) even where the environment
# sets PYTHONDONTWRITEBYTECODE: every worker and every stage subprocess a test starts would
# otherwise compile the package and rewrite the test modules again.
PYTEST := env -u PYTHONDONTWRITEBYTECODE $(PY) -m pytest -q $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --maxprocesses 4 --dist loadfile)
RUN := $(PY) -m
# NPROC > 1: data-parallel training, one process per CPU share or GPU (torchrun + DDP).
TRAIN := $(if $(filter-out 1,$(NPROC)),.venv/bin/torchrun --standalone --nproc_per_node=$(NPROC) -m,$(RUN)) pipeline.stages.train

.PHONY: help setup lint test test-slow reproduce generate label train baseline evaluate unseen ablation robustness report verify view profile bench repro-check lock clean

help: ## List the targets
	@grep -hE '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*## "}; {printf "  make %-12s %s\n", $$1, $$2}'
	@echo "  Variables: EXPERIMENT=smoke|default|paper (default: default), ARGS='hydra overrides', STAGE=<stage> (view, profile), NPROC=<n> (train), TEST_WORKERS=<n>|auto|0 (test, test-slow)"

setup: ## Create .venv with the pinned packages and check system libraries (quick if done)
	@bash scripts/setup.sh

lint: setup ## Lint and format check (ruff) and the architecture contracts (import-linter: layers, the robot's fence)
	.venv/bin/ruff check .
	.venv/bin/ruff format --check .
	.venv/bin/lint-imports --no-cache

test: setup ## Run the fast test suite on every core (what CI runs; the contracts are one of its tests)
	$(PYTEST)

test-slow: setup ## Run only the tests marked slow (`make test` runs all the others; CI runs both)
	$(PYTEST) -m slow || [ $$? -eq 5 ]  # 5: no test is marked slow

reproduce: setup ## Run every stage with EXPERIMENT (default: default), then the report
	$(RUN) pipeline.stages.generate experiment=$(EXPERIMENT) $(ARGS)
	$(RUN) pipeline.stages.label experiment=$(EXPERIMENT) $(ARGS)
	$(TRAIN) experiment=$(EXPERIMENT) $(ARGS)
	$(RUN) pipeline.stages.baseline experiment=$(EXPERIMENT) $(ARGS)
	$(RUN) pipeline.stages.evaluate experiment=$(EXPERIMENT) $(ARGS)
	$(RUN) pipeline.stages.unseen experiment=$(EXPERIMENT) $(ARGS)
	$(RUN) pipeline.stages.ablation experiment=$(EXPERIMENT) $(ARGS)
	$(RUN) pipeline.stages.robustness experiment=$(EXPERIMENT) $(ARGS)
	$(RUN) pipeline.report experiment=$(EXPERIMENT) $(ARGS)

generate: setup ## Generation stage: depth images of box heaps (paper Sec. 4.3)
	$(RUN) pipeline.stages.generate experiment=$(EXPERIMENT) $(ARGS)

label: setup ## Labelling stage: surfaces, hand- and robot-level grasp classes (Sec. 4.3)
	$(RUN) pipeline.stages.label experiment=$(EXPERIMENT) $(ARGS)

train: setup ## Training stage: the DCNN grasp planner on the labels (Secs. 4.1, 4.2); NPROC=2: torchrun
	$(TRAIN) experiment=$(EXPERIMENT) $(ARGS)

baseline: setup ## Dex-Net-style comparison: GQ-CNN + CEM suction planner and Table 2 (Sec. 8.1.1)
	$(RUN) pipeline.stages.baseline experiment=$(EXPERIMENT) $(ARGS)

evaluate: setup ## Closed-loop picking trials: descriptor, 2.5D VS, suction; Table 3 (Secs. 5, 6)
	$(RUN) pipeline.stages.evaluate experiment=$(EXPERIMENT) $(ARGS)

unseen: setup ## Unseen box sizes: Tables 1 and 2 on heaps of boxes not seen in training
	$(RUN) pipeline.stages.unseen experiment=$(EXPERIMENT) $(ARGS)

ablation: setup ## Execution ablation: each closed-loop extension on and off on the same heaps
	$(RUN) pipeline.stages.ablation experiment=$(EXPERIMENT) $(ARGS)

robustness: setup ## Robustness study: SR300 sensor noise, depth filters, Sec. 8.4 policies (Secs. 8.4, 8.5)
	$(RUN) pipeline.stages.robustness experiment=$(EXPERIMENT) $(ARGS)

report: setup ## Report stage: tables and figures into reports/
	$(RUN) pipeline.report experiment=$(EXPERIMENT) $(ARGS)

verify: setup ## Re-hash every artifact against its manifest
	$(RUN) pipeline.tools.verify $(ARGS)

view: setup ## Open the latest log of STAGE (default: generate) in the Rerun viewer
	@$(RUN) pipeline.tools.view $(STAGE) $(ARGS)

profile: setup ## Where STAGE's time goes: run it under py-spy, print each part's share (ARGS: its overrides)
	$(RUN) pipeline.tools.profile $(STAGE) $(ARGS)

bench: setup ## Print measured throughput figures (generation scenes/s, render time)
	$(RUN) pipeline.tools.bench $(ARGS)

repro-check: setup ## Run the smoke pipeline twice into fresh roots and compare every artifact
	$(RUN) pipeline.tools.repro_check $(ARGS)

lock: ## Regenerate requirements.lock from the current .venv
	$(PY) -m pip freeze --exclude-editable | sed 's/^torch==\(.*\)+cpu/torch==\1/' | \
	  (echo "# Exact versions of every package (direct and transitive), from 'pip freeze' of a working setup."; \
	   echo "# Installed by scripts/setup.sh; regenerate with 'make lock' after changing pyproject.toml."; cat) > requirements.lock

clean: ## Remove generated data, models and the environment (asks first)
	@read -p "Delete data/, models/ and .venv/? [y/N] " a && [ "$$a" = y ] && rm -rf data models .venv || true
