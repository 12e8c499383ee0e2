# Two entry points, each installing what it needs into .venv on a fresh machine:
#   make eval   -- the APF evaluated on the paper's scenario, metrics printed
#   make test   -- ruff + the whole test suite (with the ecosystem's clients: the clients extra)
# and CI's further jobs (.ci/run):
#   make test-floors  -- env, vector, convention, real-traffic and checkpoint tests on the floors
#                        (.ci/floors.txt), without numba or any extra, in a venv of their own;
#                        every test file collects there (no import error without the extras)
#   make test-package -- build wheel + sdist, twine check, install the wheel in a clean venv
#                        outside the repo and run uasep-eval on a shipped policy by name
#                        (and uasep-train / uasep-report / uasep-seeds --help there, without
#                        torch; uasep-bench and uasep-tradeoff on 2 episodes, into the cwd)
#   make test-benchmarl -- BenchMARL's MAPPO on a custom task, in a venv of its own
#   make test-omnisafe  -- OmniSafe's PPOLag on the Gymnasium view, in a venv of its own
#   make docs   -- the documentation site, warnings as errors
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
# A local CPU build; a plain "torch" requirement would pull a multi-GB CUDA build.
TORCH  := torch==2.13.0

# Outside the repository: what a pip user has (no repo on the path).
FLOORS_VENV ?= $(CURDIR)/.venv-floors
PKG_DIR     ?= /tmp/uasep-env-package-check
BENCHMARL_VENV ?= $(CURDIR)/.venv-benchmarl
OMNISAFE_VENV  ?= $(CURDIR)/.venv-omnisafe

.PHONY: eval test lint bench clean ci test-floors test-package test-benchmarl test-omnisafe docs

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
	$(BIN)/python -m pip install --quiet -e ".[dev,train,viz,fast,clients,tune]" "$(TORCH)"
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

# Every CI job, in order (.ci/run).
ci: test test-floors test-package test-benchmarl test-omnisafe docs

# The floors, exactly, and the package's requirements resolved against them (pip fails if a
# declared range excludes a floor; --dry-run: no build/ left in the tree); the tests run on
# this checkout. No numba (its kernels hide the numpy paths), no matplotlib, no torch.
$(FLOORS_VENV)/.floors: .ci/floors.txt pyproject.toml
	rm -rf $(FLOORS_VENV)
	$(PYTHON) -m venv $(FLOORS_VENV)
	$(FLOORS_VENV)/bin/python -m pip install --quiet -r .ci/floors.txt "pytest>=8"
	$(FLOORS_VENV)/bin/python -m pip install --quiet --dry-run -c .ci/floors.txt .
	touch $@

FLOORS_TESTS := tests/test_envs.py tests/test_vector.py tests/test_conventions.py \
	tests/test_config.py tests/test_packaging.py tests/test_replay.py tests/test_real_traffic.py \
	tests/test_banks.py tests/test_shipped.py tests/test_pinned_numbers.py \
	tests/test_checkpoint_layout.py tests/test_checkpoint_limits.py tests/test_costs.py

# Then a plain pytest without any extra (what a pip user runs on the sdist) collects every test
# file: tests needing an extra skip (pytest.importorskip, conftest's hypothesis stand-ins),
# none fails to import.
test-floors: $(FLOORS_VENV)/.floors
	@! $(FLOORS_VENV)/bin/python -c "import numba" 2>/dev/null || (echo "numba in the floors venv" && false)
	$(FLOORS_VENV)/bin/python -m pip list --format=freeze | grep -iE "^(numpy|gymnasium|pettingzoo|scipy|tabulate)=="
	cd $(CURDIR) && $(FLOORS_VENV)/bin/python -m pytest -q -p no:cacheprovider $(FLOORS_TESTS)
	cd $(CURDIR) && $(FLOORS_VENV)/bin/python -m pytest -qq -p no:cacheprovider --collect-only \
		tests > $(FLOORS_VENV)/collect.log 2>&1 || (tail -30 $(FLOORS_VENV)/collect.log && false)

# sdist, then the wheel built from it (so the sdist is complete); the clean venv takes the
# wheel's dependencies from pip's cache after the first run.
test-package: $(VENV)/.all
	rm -rf $(PKG_DIR) && mkdir -p $(PKG_DIR)
	$(BIN)/python -m build --outdir $(PKG_DIR)/dist . > $(PKG_DIR)/build.log
	$(BIN)/twine check --strict $(PKG_DIR)/dist/*
	$(BIN)/python tools/check_dist.py $(PKG_DIR)/dist
	$(PYTHON) -m venv $(PKG_DIR)/venv
	$(PKG_DIR)/venv/bin/python -m pip install --quiet $(PKG_DIR)/dist/*.whl
	cd $(PKG_DIR) && venv/bin/uasep-eval --policy ppo_residual_apf,apf \
		--config episode_duration=20 --json run.json
	cd $(PKG_DIR) && ! venv/bin/python -c "import matplotlib" 2>/dev/null
	cd $(PKG_DIR) && ! venv/bin/python -c "import torch" 2>/dev/null
	cd $(PKG_DIR) && for r in "" ppo_shared ppo_residual_apf mappo; do \
		venv/bin/uasep-train $$r --help > train_help.txt || exit 1; done
	cd $(PKG_DIR) && grep -q -- "--checkpoint-every CHECKPOINT_EVERY" train_help.txt
	cd $(PKG_DIR) && venv/bin/uasep-report --help | grep -q -- "--held-out-episodes"
	cd $(PKG_DIR) && venv/bin/uasep-bench --help > /dev/null && venv/bin/uasep-tradeoff --help \
		> /dev/null && venv/bin/uasep-seeds --help | grep -q -- "--from-json"
	cd $(PKG_DIR) && venv/bin/uasep-bench --policy apf --banks held_out --episodes 2 --no-front \
		--no-figure --quiet --out bench && test -s bench/bench.json
	cd $(PKG_DIR) && venv/bin/uasep-tradeoff --methods apf --paper-episodes 2 --bank-episodes 2 \
		--workers 1 --no-figures > tradeoff.log && test -s tradeoff/tradeoff.csv \
		&& test -s tradeoff/tradeoff.md
	cd $(PKG_DIR) && mkdir sdist && tar xzf dist/*.tar.gz -C sdist --strip-components 1
	cd $(PKG_DIR)/sdist && $(abspath $(BIN))/python -m pytest -q -p no:cacheprovider \
		--collect-only tests > collect.log || (tail -30 collect.log && false)
	cd $(PKG_DIR)/sdist && UASEP_NUMBA=0 $(abspath $(BIN))/python -m pytest -q \
		-p no:cacheprovider tests/test_packaging.py -k "shipped or metadata or links or floors"

# BenchMARL's MAPPO on a custom task (tests/test_benchmarl.py): BenchMARL pins TorchRL 0.11,
# the clients extra 0.14, so it gets a venv of its own.
$(BENCHMARL_VENV)/.benchmarl: pyproject.toml
	rm -rf $(BENCHMARL_VENV)
	$(PYTHON) -m venv $(BENCHMARL_VENV)
	$(BENCHMARL_VENV)/bin/python -m pip install --quiet $(TORCH)
	$(BENCHMARL_VENV)/bin/python -m pip install --quiet -e ".[benchmarl]" "$(TORCH)"
	touch $@

test-benchmarl: $(BENCHMARL_VENV)/.benchmarl
	UASEP_REQUIRE_BENCHMARL=1 UASEP_NUMBA=0 $(BENCHMARL_VENV)/bin/python -m pytest -q \
		-p no:cacheprovider tests/test_benchmarl.py

# OmniSafe 0.5.0's PPOLag on uasep_env.clients.omnisafe (tests/test_omnisafe.py). OmniSafe
# requires safety-gymnasium 1.0.0, which pins gymnasium 0.28.1 (the package needs >= 1.1) and
# pygame 2.1.0 (no build on Python 3.11), and pandas==2.0.3 (numpy 1 only): so OmniSafe goes
# in last with --no-deps, after what it imports (.ci/omnisafe.txt); the client module stands
# in for safety_gymnasium.
$(OMNISAFE_VENV)/.omnisafe: pyproject.toml .ci/omnisafe.txt
	rm -rf $(OMNISAFE_VENV)
	$(PYTHON) -m venv $(OMNISAFE_VENV)
	$(OMNISAFE_VENV)/bin/python -m pip install --quiet $(TORCH)
	$(OMNISAFE_VENV)/bin/python -m pip install --quiet -e . -r .ci/omnisafe.txt "$(TORCH)"
	$(OMNISAFE_VENV)/bin/python -m pip install --quiet --no-deps omnisafe==0.5.0
	touch $@

test-omnisafe: $(OMNISAFE_VENV)/.omnisafe
	UASEP_REQUIRE_OMNISAFE=1 UASEP_NUMBA=0 $(OMNISAFE_VENV)/bin/python -m pytest -q \
		-p no:cacheprovider tests/test_omnisafe.py

# The documentation site (Sphinx), warnings as errors; the pages' examples run in make test.
docs: $(VENV)/.all
	$(BIN)/python -m pip install --quiet -e ".[docs]" "$(TORCH)"
	$(BIN)/python -m sphinx -b html -W --keep-going -q docs docs/_build/html
	$(BIN)/python tools/check_built_docs.py docs/_build/html  # links resolve, tables scroll

bench: $(VENV)/.all
	$(BIN)/python -m pip install --quiet -e ".[bench]"
	$(BIN)/python benchmarks/bench_peers.py

clean:
	rm -rf $(VENV) $(FLOORS_VENV) $(BENCHMARL_VENV) $(OMNISAFE_VENV) .pytest_cache .ruff_cache .hypothesis
