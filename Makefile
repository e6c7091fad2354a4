# make run   : set up (first time), train a first agent on CPU (pendulum, composite hint, FiLM) and show it
# make setup-gpu : the same set-up on an NVIDIA GPU machine: jax's CUDA plugin and warp-lang (MJX-Warp physics) too
# make test  : set up (first time) and run the test suite (slow tests: make test-slow)
# make lint  : set up (first time) and run ruff's checks and its formatter's check (pinned in pyproject.toml)
# make bench : environment and training throughput (meant for a GPU)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
GPU_STAMP := $(VENV)/.installed-gpu-stamp

.PHONY: setup setup-gpu run test test-slow lint bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

setup: $(STAMP)

$(GPU_STAMP): $(STAMP)
	$(BIN)/pip install --quiet -e '.[test,gpu]'
	touch $(GPU_STAMP)

setup-gpu: $(GPU_STAMP)

# A first agent that learns on CPU (python -m hintsjax.quickstart): pendulum, composite hint, FiLM,
# 36x36 pictures, one seed, 32 updates of 3200 env steps, evaluated beside a random policy, with a GIF.
run: setup
	$(BIN)/python -m hintsjax.quickstart

# Two processes, one test file each at a time (module fixtures stay shared): compiling is
# single-threaded, so two processes use 2 cores (the time: README.md, "Reliability"). Each tier
# ends with its 25 longest tests, so a CI log shows where its minutes went.
test: setup
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --durations=25

# The slow tier's files hold several long tests each (8 drives in one): spread test by test.
test-slow: setup
	$(BIN)/python -m pytest -q -m slow -n 2 --dist load --durations=25

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

BENCH_ENVS ?= pendulum,acrobot,idp,halfcheetah,ant,ant_fast,humanoid,car_racing
bench: setup
	$(BIN)/python experiments/bench.py --envs $(BENCH_ENVS)

clean:
	rm -rf $(VENV) runs
