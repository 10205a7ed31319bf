# Two commands set everything up: `make demo` and `make test`.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
export PYTHONUNBUFFERED := 1
# Two pytest workers (CI has 2 cores); a whole test file stays on one worker so that its
# module-scoped fits are computed once. The 25 slowest tests are listed at the end (CI's budget is
# 90 minutes on 2 cores; the suite took 63-76 of them in sessions 31-32): read, never asserted.
PYTEST_ARGS ?= -n 2 --dist loadfile --durations=25 --durations-min=10

.PHONY: all venv test lint demo bench experiments fuzz clean

all: test

$(STAMP): pyproject.toml requirements.lock
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c requirements.lock -e ".[dev]"
	@touch $(STAMP)

venv: $(STAMP)

lint: $(STAMP)
	$(VENV)/bin/ruff check fourierjax tests experiments

test: lint
	$(PY) -m pytest $(PYTEST_ARGS)

demo: $(STAMP)
	$(VENV)/bin/fourierjax demo --out out/demo

bench: $(STAMP)
	$(PY) -m experiments.benchmarks --out out/bench

# The large fuzz and fault run (tests/fuzz): >= 10,000 mutated BVH files, 1,000 mutated model
# files and 500 CLI argument sets; prints the counts and fails on any untyped exception.
fuzz: $(STAMP)
	$(PY) -m tests.fuzz --bvh 10000 --models 1000 --cli 500

experiments: $(STAMP)
	$(PY) -m experiments --out out/experiments

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache .hypothesis
