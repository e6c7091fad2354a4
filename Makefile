# make run   : set up (first time) and train the default agent (pendulum, composite hint, FiLM) on CPU
# make test  : set up (first time) and run the test suite (slow tests: make test-slow)
# make lint  : set up (first time) and run ruff (pinned in pyproject.toml) over the repository
# make bench : environment and training throughput (meant for a GPU)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: setup run test test-slow lint bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test]'
	touch $(STAMP)

setup: $(STAMP)

# A CPU-sized budget: 1 seed, 50 updates of 1024 transitions (about 5 minutes on 2 cores).
run: setup
	$(BIN)/python -m hintsjax.run env=pendulum agent=hints hint=composite scheme=fc \
		seeds=1 eval_episodes=20 ppo.total_env_steps=51200 ppo.epochs=4 checkpoint_every=5

# Two processes, one test file each at a time (module fixtures stay shared): compiling is
# single-threaded, so this takes 9 to 11 minutes on 2 cores (before the locomotion and car
# tests it was 8.5 against 10.5 minutes in one process).
test: setup
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

test-slow: setup
	$(BIN)/python -m pytest -q -m slow -n 2 --dist loadfile

lint: setup
	$(BIN)/ruff check .

BENCH_ENVS ?= pendulum,acrobot,idp,halfcheetah,ant,ant_fast,humanoid,car_racing
bench: setup
	$(BIN)/python experiments/bench.py --envs $(BENCH_ENVS)

clean:
	rm -rf $(VENV) runs
