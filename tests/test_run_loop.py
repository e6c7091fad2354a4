"""The run loop's pieces: a masked chunk equals the plain updates, the compilation cache's
settings and its bad folders, and a failed background checkpoint write."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import time
import warnings

import jax
import numpy as np
import orbax.checkpoint as ocp
import pytest

import linear_env  # noqa: F401  (registers the test env "linear")
from hintsjax.system import checkpoint, compilation_cache
from hintsjax.settings import layers
from hintsjax.settings.layers import run_config
from hintsjax.algorithms.registry import make_trainer
from hintsjax.training import guards, loop, outputs, pipeline
from hintsjax import run

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


def test_a_masked_chunk_equals_its_first_updates_and_skips_the_rest(trainer):
    """3 of 5 updates in one program give the state of 3 plain updates; the 2 skipped ones leave
    the state alone and log NaN (0 for integer metrics). Equal to float32 rounding, not bit for
    bit: at the test tier's -O0 the two programs compile the rollout's while loop (the ended
    envs' fresh starts) apart and round a start's draw differently; one more update would be a
    change of 1e-3, not 1e-9 (a resumed run, which runs the same programs, is bit for bit:
    tests/test_cli.py)."""
    state = trainer.init(jax.random.key(3))
    plain, plain_metrics = jax.jit(trainer.run, static_argnums=1)(state, 3)
    masked, metrics = jax.jit(trainer.run_chunk, static_argnums=2)(state, np.int32(3), 5)
    for a, b in zip(
        jax.tree.leaves(jax.tree.map(_data, plain)), jax.tree.leaves(jax.tree.map(_data, masked))
    ):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-6, atol=1e-7)
    assert int(masked.update) == 3
    np.testing.assert_allclose(
        metrics["policy_loss"][:3], plain_metrics["policy_loss"], rtol=1e-5, atol=1e-7
    )
    assert np.all(np.isnan(metrics["policy_loss"][3:])) and np.all(
        np.asarray(metrics["episodes"][3:]) == 0
    )


def _data(x):
    return jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x


def test_compilation_cache_settings(monkeypatch, tmp_path):
    monkeypatch.delenv(compilation_cache.ENV_VAR, raising=False)
    assert compilation_cache.folder(True) == str(compilation_cache.DEFAULT)
    assert compilation_cache.folder(None) is None and compilation_cache.folder(False) is None
    assert compilation_cache.folder("off") is None and compilation_cache.folder(
        str(tmp_path)
    ) == str(tmp_path)
    monkeypatch.setenv(compilation_cache.ENV_VAR, "off")
    assert compilation_cache.folder(True) is None
    monkeypatch.setenv(compilation_cache.ENV_VAR, str(tmp_path / "c"))
    assert compilation_cache.folder(True) == str(tmp_path / "c")


def test_a_cache_folder_that_cannot_be_made_turns_the_cache_off_with_one_line(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert compilation_cache.enable(blocker / "cache") is None
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: compilation cache off")


CACHED = """
import sys, jax, jax.numpy as jnp
from hintsjax.system import compilation_cache
compilation_cache.enable(sys.argv[1], min_compile_seconds=0)
f = jax.jit(lambda x: jnp.cumsum(jnp.sin(x) * 3.0) @ jnp.cos(x))
print(float(f(jnp.arange(64.0))))
"""


def test_a_corrupt_cache_entry_is_compiled_afresh_with_the_right_result(tmp_path):
    """A cache whose entries are garbage (another writer's truncated files, a disk error) costs
    a compile and a warning, never a crash or a wrong program."""
    cache = tmp_path / "cache"

    def once() -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-c", CACHED, str(cache)], capture_output=True, text=True, timeout=120
        )

    first = once()
    assert first.returncode == 0, first.stderr
    entries = [p for p in cache.rglob("*") if p.is_file() and not p.name.startswith(".")]
    assert entries, "nothing was cached"
    for p in entries:
        p.write_bytes(b"not an executable" * 3)
    second = once()
    assert second.returncode == 0, second.stderr
    assert second.stdout == first.stdout and "Traceback" not in second.stderr


def test_a_failed_background_write_stops_the_run_with_one_line_and_keeps_the_last_checkpoint(
    tmp_path, monkeypatch, capsys
):
    real_save, calls = ocp.CheckpointManager.save, []

    def fail_after_first(self, step, *args, **kwargs):
        calls.append(step)
        if len(calls) > 1:
            raise OSError(28, "No space left on device")
        return real_save(self, step, *args, **kwargs)

    monkeypatch.setattr(ocp.CheckpointManager, "save", fail_after_first)
    values = {
        "env": "linear",
        "agent": "ppo_state",
        "seeds": 2,
        "eval_episodes": 2,
        "checkpoint_every": 1,
        "checkpoint_seconds": 0,
        "ppo": TINY_PPO,
        "out_dir": str(tmp_path),
        "name": "r",
    }
    assert run.main_from_values(values) == 1
    err = capsys.readouterr().err
    # the rest is the progress bar
    errors = [line for line in err.splitlines() if line.startswith("error")]
    assert len(errors) == 1 and "No space left on device" in errors[0], err
    assert errors[0].startswith("error: could not write checkpoint") and "Traceback" not in err
    monkeypatch.setattr(ocp.CheckpointManager, "save", real_save)
    assert checkpoint.latest_update(tmp_path / "r") == calls[0]
    assert not (tmp_path / "r" / outputs.EVAL_JSON).exists()
    assert json.loads((tmp_path / "r" / loop.SECONDS_JSON).read_text())["update"] == calls[0]


def test_orbax_s_unawaited_writes_of_a_failed_checkpoint_are_not_reported(tmp_path):
    """A failed background write can leave orbax's per-array writes unstarted; each printed
    "coroutine '...write_fragment' was never awaited" when collected, even at exit (once in CI under
    ulimit -f). Inside `writing` (and after) only those are dropped: another unawaited coroutine is
    reported."""

    def dropped_coroutine(name: str):
        async def coro():
            pass

        c = coro()
        c.__qualname__ = f"async_serialize_from_host.<locals>.{name}"  # as Python names orbax's
        del c  # collected now, unawaited: Python warns here

    with warnings.catch_warnings(record=True) as seen:
        with checkpoint.writing(tmp_path / "r"):
            dropped_coroutine("write_fragment")
            dropped_coroutine("read_fragment")
        dropped_coroutine("write_fragment")
    said = [str(w.message) for w in seen if w.category is RuntimeWarning]
    assert said == [
        "coroutine 'async_serialize_from_host.<locals>.read_fragment' was never awaited"
    ], said


def test_a_run_resumed_at_its_last_update_only_evaluates(tmp_path):
    """A run killed during its evaluation resumes at its end: nothing is trained or saved again."""
    values = {
        "env": "linear",
        "agent": "ppo_state",
        "seeds": 2,
        "eval_episodes": 2,
        "checkpoint_every": 2,
        "checkpoint_seconds": 0,
        "ppo": TINY_PPO,
        "out_dir": str(tmp_path),
        "name": "r",
    }
    assert run.main_from_values(values) == 0
    folder = tmp_path / "r"
    first = json.loads((folder / outputs.EVAL_JSON).read_text())
    (folder / outputs.EVAL_JSON).unlink()
    rows = (folder / "metrics.csv").read_text()
    assert run.main_from_values({"resume": str(folder)}) == 0
    again = json.loads((folder / outputs.EVAL_JSON).read_text())
    assert (
        again["evaluations"] == first["evaluations"]
        and (folder / "metrics.csv").read_text() == rows
    )
    # 3 chunks; none
    assert first["chunks_env_steps_per_s"] > 0 and again["chunks_env_steps_per_s"] is None
    assert checkpoint.latest_update(folder) == 5


def test_chunks_rate_runs_from_training_start_to_the_last_chunks_metrics():
    """6 updates of 100 env steps, the last chunk's metrics on the host at 3.0 s (its checkpoint
    written after, at 9.0 s): 200 steps/s; a resumed call from update 2 trained 4 of them; no
    chunk, no rate."""
    training = loop.Training(
        compiled=None,
        state=None,
        done=6,
        first=0,
        before=0.0,
        seconds=9.0,
        arrivals=((1.0, 2), (2.5, 4), (3.0, 6)),
    )
    assert loop.chunks_rate(training, 100) == pytest.approx(200.0)
    assert loop.chunks_rate(dataclasses.replace(training, first=2), 100) == pytest.approx(400 / 3)
    assert loop.chunks_rate(dataclasses.replace(training, arrivals=()), 100) is None


def nonfinite_values(tmp_path, **ppo) -> dict:
    """A 5-update run on the linear test env, checkpointed every 2 updates."""
    return {
        "env": "linear",
        "agent": "ppo_state",
        "seeds": 2,
        "eval_episodes": 2,
        "checkpoint_every": 2,
        "checkpoint_seconds": 0,
        "out_dir": str(tmp_path),
        "name": "nan",
        "ppo": {**TINY_PPO, **ppo},
    }


def test_a_run_that_goes_non_finite_stops_keeps_its_last_good_checkpoint_and_says_where(
    tmp_path, monkeypatch, capsys
):
    """Every seed's params turn NaN at the end of update 3: update 4's losses are NaN, the run stops
    there with one line and exit 1, its newest checkpoint is update 2's (all finite), nothing of
    update 3 or later is saved and nothing is evaluated; nonfinite.json says what and where."""
    import jax.numpy as jnp

    real = pipeline.make_trainer

    def poisoned(cfg):
        trainer = real(cfg)

        def update(state):
            state, metrics = trainer.update(state)
            bad = state.update == 3
            return state.replace(
                params=jax.tree.map(lambda x: jnp.where(bad, jnp.nan, x), state.params)
            ), metrics

        return dataclasses.replace(trainer, update=update)

    monkeypatch.setattr(pipeline, "make_trainer", poisoned)
    assert run.main_from_values(nonfinite_values(tmp_path)) == 1
    # the rest: the progress bar
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert (
        len(err) == 1 and err[0].startswith("error: ") and "not finite after update 4" in err[0]
    ), err
    assert "last good checkpoint: update 2" in err[0] and "Traceback" not in err[0]
    folder = tmp_path / "nan"
    record = json.loads((folder / guards.NONFINITE_JSON).read_text())
    assert record == {
        "update": 4,
        "quantity": "policy_loss",
        "seeds": [0, 1],
        "last_good_checkpoint": 2,
    }
    assert checkpoint.latest_update(folder) == 2 and not (folder / outputs.EVAL_JSON).exists()
    cfg = layers.load_run_config(folder)
    state, _ = checkpoint.restore_latest(folder, make_trainer(cfg).abstract_state())
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(state.params))


def test_a_checkpoint_of_non_finite_params_is_never_written(tmp_path):
    """The check beside the losses: params that are not finite are refused at the save, whatever
    the losses said (one seed's NaN names that seed)."""
    cfg = run_config({"env": "linear", "agent": "ppo_state", "seeds": 2, "ppo": TINY_PPO})
    state = jax.jit(jax.vmap(make_trainer(cfg).init))(cfg.seed_keys())
    assert np.asarray(guards.finite_seeds(state.params)).tolist() == [True, True]
    poisoned = jax.tree.map(lambda x: x.at[1].set(np.inf), state.params)
    assert np.asarray(guards.finite_seeds(poisoned)).tolist() == [True, False]
    found = guards.first_nonfinite(
        {
            "policy_loss": np.array([[0.1, 0.2], [0.3, np.nan]]),
            "episode_return": np.full((2, 2), np.nan),
        },
        after=6,
    )
    assert found == {"update": 8, "quantity": "policy_loss", "seeds": [1]}
    group = guards.first_nonfinite(
        {"value_loss": np.array([[[0.1, 0.1, np.inf]], [[0.2, 0.2, 0.2]]])}, after=0
    )
    assert group == {"update": 1, "quantity": "value_loss", "seeds": [0], "members": [2]}


def test_a_learning_rate_that_blows_up_is_caught_by_the_same_check(tmp_path, capsys):
    """No injection: learning rates of 1e30 drive the params to infinity within the first update."""
    values = nonfinite_values(tmp_path, encoder_lr=1e30, actor_lr=1e30, critic_lr=1e30)
    assert run.main_from_values(values) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert (
        len(err) == 1
        and "is not finite after update 1" in err[0]
        and "last good checkpoint: none" in err[0]
    ), err
    assert checkpoint.latest_update(tmp_path / "nan") is None


def test_process_age_counts_from_the_process_start():
    """hintsjax.system.wall.process_age in a process that waited 0.5 s before asking: at least
    that, and less than the whole subprocess took; Laps name each stage by its end."""
    code = (
        "import time; time.sleep(0.5); from hintsjax.system.wall import process_age; "
        "print(process_age())"
    )
    t = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    # /proc gives the start in clock ticks: the age may be one over
    tick = 1 / os.sysconf("SC_CLK_TCK")
    assert 0.5 <= float(out) <= time.perf_counter() - t + tick
    from hintsjax.system.wall import Laps

    laps = Laps()
    time.sleep(0.05)
    laps.mark("first")
    laps.mark("second")
    assert (
        list(laps.seconds) == ["startup", "first", "second"]
        and laps.seconds["first"] >= 0.05 > laps.seconds["second"]
    )
