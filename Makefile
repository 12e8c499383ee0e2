# Two entry points, each installing what it needs into .venv on a fresh machine:
#   make eval   -- the APF evaluated on the paper's scenario, metrics printed
#   make test   -- ruff + the whole test suite (with the ecosystem's clients: the clients extra)
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
# A local CPU build; a plain "torch" requirement would pull a multi-GB CUDA build.
TORCH  := torch==2.13.0

.PHONY: eval test lint bench clean docs

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# Core + plotting + compiled kernels: what the evaluation needs (no torch).
$(VENV)/.core: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[viz,fast]"
	$(BIN)/python -m uasep_env.precompile  # compile the kernels at install time (disk cache)
	touch $@

# Everything: torch first, then the package with every extra the tests use (torch pinned
# again so that no client upgrades it to a CUDA build).
$(VENV)/.all: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet $(TORCH)
	$(BIN)/python -m pip install --quiet -e ".[dev,train,viz,fast,clients]" "$(TORCH)"
	$(BIN)/python -m uasep_env.precompile
	touch $@ $(VENV)/.core

eval: $(VENV)/.core
	$(BIN)/uasep-eval --policy apf --scenario paper --episodes 1 --seed 0

lint: $(VENV)/.all
	$(BIN)/ruff check .
	$(BIN)/ruff format --check uasep_env

# The client tests must run (not skip) here; the Ray tests share one local Ray per worker.
test: lint
	UASEP_REQUIRE_CLIENTS=1 $(BIN)/python -m pytest -n 2 --dist loadgroup -q

# The documentation site (Sphinx), warnings as errors; the pages' examples run in make test.
docs: $(VENV)/.all
	$(BIN)/python -m pip install --quiet -e ".[docs]" "$(TORCH)"
	$(BIN)/python -m sphinx -b html -W --keep-going -q docs docs/_build/html

bench: $(VENV)/.all
	$(BIN)/python -m pip install --quiet -e ".[bench]"
	$(BIN)/python benchmarks/bench_peers.py

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis
