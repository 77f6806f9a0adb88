# sb3-es developer tasks. `make train` and `make test` each set up .venv first.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.stamp
LINT_PATHS := $(wildcard sb3_es tests benchmarks examples)

.DEFAULT_GOAL := help
.PHONY: help venv train test lint typecheck docs bench conformance clean

help:
	@echo "make train      set up .venv and run a short ARS training (TensorBoard logs + saved model)"
	@echo "make test       set up .venv, run lint, type checks, docs build and the test suite"
	@echo "make lint       ruff check + ruff format --check"
	@echo "make typecheck  mypy"
	@echo "make docs       build the Sphinx docs into docs/_build/html"
	@echo "make bench      throughput ratios (benchmarks/throughput.py, about 5 min; BENCH_ARGS=--quick)"
	@echo "make conformance  run the pinned stable-baselines3 / sb3-contrib test files on sb3-es (downloads them)"
	@echo "make clean      remove build outputs and caches (keeps .venv)"

venv: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	@test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip install -c constraints.txt -e ".[dev]"
	@touch $(STAMP)

train: venv
	$(BIN)/python -m sb3_es.cli quickstart

test: venv
	$(MAKE) lint
	$(MAKE) typecheck
	$(MAKE) docs
	$(BIN)/python -m pytest -q --durations=15  # the slowest tests: the suite should stay under about 10 minutes

lint: venv
	$(BIN)/ruff check $(LINT_PATHS)
	$(BIN)/ruff format --check $(LINT_PATHS)

typecheck: venv
	$(BIN)/mypy

docs: venv
	$(BIN)/sphinx-build -W --keep-going -b html docs docs/_build/html

# Throughput ratios against sb3-contrib's ARS and the plain step loop, measured in one run (about 5 minutes).
# The learning benchmarks (hours) are separate commands: docs/benchmarks.md.
bench: venv
	$(BIN)/python benchmarks/throughput.py $(BENCH_ARGS)

# Downloads the pinned SB3 and sb3-contrib source distributions from PyPI at run time (their tests are never
# committed) and runs them with sb3-es's classes substituted (tests/conformance/). Not part of `make test`.
conformance: venv
	$(BIN)/python tests/conformance/run.py $(CONFORMANCE_ARGS)

clean:
	rm -rf docs/_build build dist *.egg-info .pytest_cache .mypy_cache .ruff_cache
	find . -path ./$(VENV) -prune -o -type d -name __pycache__ -exec rm -rf {} +
