"""The traced-program cache (hintsjax/system/program_cache.py): a program loaded from it computes
what the program traced afresh computes, bit for bit; a second process loads the run's programs
instead of tracing them; a changed source, an undescribable program, a registered hint without
a source file and a corrupt entry are never served from it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from functools import partial
from pathlib import Path

import jax
import numpy as np
import pytest

import linear_env  # noqa: F401  (registers the test env "linear")
from hintsjax.envs import hints as hints_module
from hintsjax.system import program_cache
from hintsjax.settings.layers import run_config
from hintsjax.algorithms.registry import make_trainer

TINY_PPO = {
    "total_env_steps": 320,
    "num_envs": 4,
    "batch_size": 64,
    "minibatch_size": 32,
    "epochs": 1,
}


@pytest.fixture(scope="module")
def trainer():
    return make_trainer(
        run_config({"env": "linear", "agent": "ppo_state", "seeds": 2, "ppo": TINY_PPO})
    )


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A cache folder of this test's own (the suite runs with the cache off)."""
    monkeypatch.setattr(program_cache, "folder", lambda: tmp_path / "traced")
    return tmp_path / "traced"


def _leaves(tree):
    return [
        np.asarray(
            jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
        )
        for x in jax.tree.leaves(tree)
    ]


def _chunk(trainer):
    return jax.vmap(partial(trainer.run_chunk, length=3), in_axes=(0, None))


def _run(lowered_init, lowered_chunk, keys):
    """init, then one chunk of 2 of its 3 updates, from the two lowered programs; the state is
    placed as the chunk expects, as a resumed run's restored state is (loop.start_training)."""
    state = lowered_init.compile()(keys)
    chunk = lowered_chunk.compile()
    return chunk(jax.device_put(state, chunk.input_shardings[0][0]), np.int32(2))


def test_a_loaded_program_computes_what_plain_jit_computes(trainer, cache):
    keys = trainer.cfg.seed_keys()
    init_fn = jax.vmap(trainer.init)
    lowered = []
    for _ in range(2):  # traced and kept, then loaded from the file the first call wrote
        init = program_cache.lower(init_fn, keys, name="init", context=trainer.identity)
        chunk = program_cache.lower(
            _chunk(trainer), init.out_info, np.int32(3), name="chunk3", context=trainer.identity
        )
        lowered.append((init, chunk))
    assert [(i.loaded, c.loaded) for i, c in lowered] == [(False, False), (True, True)]
    assert len(list(cache.glob("*.bin"))) == 2
    plain_init = jax.jit(init_fn).lower(keys)
    plain = _run(plain_init, jax.jit(_chunk(trainer)).lower(plain_init.out_info, np.int32(3)), keys)
    # the traced pair compiles the same program (the two-process test below)
    got = _run(*lowered[1], keys)
    assert jax.tree.structure(got) == jax.tree.structure(plain)
    for a, b in zip(_leaves(got), _leaves(plain)):
        np.testing.assert_array_equal(a, b)


def test_another_source_another_key_and_an_undescribed_program_is_never_kept(
    trainer, cache, monkeypatch
):
    keys = trainer.cfg.seed_keys()
    init_fn = jax.vmap(trainer.init)
    assert not program_cache.lower(init_fn, keys, name="init", context=trainer.identity).loaded
    assert program_cache.lower(init_fn, keys, name="init", context=trainer.identity).loaded
    monkeypatch.setattr(program_cache, "sources_digest", lambda: "an edited source file")
    assert not program_cache.lower(init_fn, keys, name="init", context=trainer.identity).loaded
    assert len(list(cache.glob("*.bin"))) == 2
    plain = program_cache.lower(init_fn, keys, name="init", context=None)
    assert isinstance(plain, jax.stages.Lowered) and len(list(cache.glob("*.bin"))) == 2
    assert (
        program_cache.lower(init_fn, keys[:1], name="init", context=trainer.identity).in_tree
        is not None
    )
    assert len(list(cache.glob("*.bin"))) == 3  # other shapes, another entry


def test_a_registered_hint_without_a_source_file_turns_the_cache_off(monkeypatch):
    assert program_cache.sources_digest() is not None
    monkeypatch.setattr(
        hints_module, "_HINTS", {k: dict(v) for k, v in hints_module._HINTS.items()}
    )
    namespace = {}
    # as a notebook cell defines it
    exec("def typed_in(state, params):\n    return state", namespace)
    hints_module.register_hint("linear", "typed_in", dim=1, unit="-")(namespace["typed_in"])
    assert program_cache.sources_digest() is None
    assert program_cache.program_key("init", "anything", [], jax.tree.structure(())) is None


def test_imitation_and_learned_hint_runs_are_not_described(trainer):
    from hintsjax.algorithms.trainer import program_identity

    cfg = trainer.cfg
    assert program_identity(cfg) is not None
    assert program_identity(run_config({"env": "pendulum", "agent": "dagger"})) is None


def test_a_corrupt_entry_is_traced_again_with_one_warning_line(trainer, cache, capsys):
    keys = trainer.cfg.seed_keys()
    init_fn = jax.vmap(trainer.init)
    first = program_cache.lower(init_fn, keys, name="init", context=trainer.identity).compile()(
        keys
    )
    (entry,) = cache.glob("*.bin")
    entry.write_bytes(b"half a file")
    again = program_cache.lower(init_fn, keys, name="init", context=trainer.identity)
    err = capsys.readouterr().err.strip().splitlines()
    assert not again.loaded and len(err) == 1 and err[0].startswith("warning: traced program")
    for a, b in zip(_leaves(again.compile()(keys)), _leaves(first)):
        np.testing.assert_array_equal(a, b)
    # rewritten whole
    assert program_cache.lower(init_fn, keys, name="init", context=trainer.identity).loaded


RUN = """
import json, sys
import linear_env  # noqa: F401  (tests/ is on PYTHONPATH)
from hintsjax import run
values = json.loads(sys.argv[1])
assert run.main_from_values(values) == 0
"""


def test_a_second_process_loads_the_runs_programs_and_trains_the_same(tmp_path):
    """The command's own path: a second run of the same configuration in a new process traces
    neither its training nor its evaluation programs, and its evaluations and learning curve
    equal the first run's."""
    env = {k: v for k, v in os.environ.items() if k != program_cache.ENV_VAR}
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(Path(__file__).parent), env.get("PYTHONPATH")) if p
    )
    results = []
    for name in ("first", "second"):
        values = {
            "env": "linear",
            "agent": "ppo_state",
            "seeds": 2,
            "eval_episodes": 2,
            "checkpoint_every": 3,
            "ppo": TINY_PPO,
            "out_dir": str(tmp_path),
            "name": name,
            "compilation_cache": str(tmp_path / "xla"),
        }
        done = subprocess.run(
            [sys.executable, "-c", RUN, json.dumps(values)],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr
        results.append(
            (
                json.loads((tmp_path / name / "eval.json").read_text()),
                (tmp_path / name / "metrics.csv").read_text(),
            )
        )
    (first, first_csv), (second, second_csv) = results
    assert not first["traced_programs_loaded"] and second["traced_programs_loaded"]
    assert second["evaluations"] == first["evaluations"] and second_csv == first_csv
    # init, chunk, evaluation
    assert len(list((tmp_path / "xla" / program_cache.FOLDER).glob("*.bin"))) == 3
