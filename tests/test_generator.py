"""The learned hint generator (hintsjax.generator, read by hintsjax.settings.hint_sources): it
learns a hint that the picture determines, its training is the same vmapped as looped, the env that
carries its pictures keeps the task's dynamics, and an agent given `hint_source` sees the
generator's hint and nothing else."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import cue_env  # noqa: F401  (registers the test env "cue")
import dot_env  # noqa: F401  (registers the test env "dot": the hint is the dot's position in the picture)
from hintsjax.system.errors import UsageError
from hintsjax.settings import hint_sources
from hintsjax.settings.layers import run_config
from hintsjax.algorithms import ppo
from hintsjax.hints import generators
from hintsjax import envs, evaluate, generator, run

TINY = dict(
    env="dot",
    hint="position",
    num_envs=4,
    steps=16,
    held_out_envs=2,
    epochs=2,
    minibatch_size=16,
    hidden=16,
)
TINY_PPO = {
    "total_env_steps": 2 * 64,
    "num_envs": 4,
    "batch_size": 64,
    "minibatch_size": 32,
    "epochs": 1,
}
CONSTANT = 7.0  # the crafted generator's output: the dot's true position is in [-1, 1], never this


def test_generator_reads_the_dot_position_from_one_picture():
    cfg = generators.GeneratorConfig(
        env="dot",
        hint="position",
        frames=1,
        num_envs=16,
        steps=32,
        held_out_envs=8,
        epochs=15,
        minibatch_size=64,
        lr=1e-3,
        hidden=64,
    ).validate()
    _, metrics = jax.jit(generators.make_train(cfg))(jax.random.key(0))
    assert float(metrics.heldout_r2[0]) > 0.99
    assert float(metrics.loss[-1]) < float(metrics.loss[0]) / 10


def test_training_vmapped_over_seeds_equals_a_loop():
    cfg = generators.GeneratorConfig(frames=2, **TINY).validate()
    train = jax.jit(generators.make_train(cfg))
    keys = jnp.stack([jax.random.key(i) for i in range(2)])
    batched = jax.jit(jax.vmap(generators.make_train(cfg)))(keys)
    for i in range(2):
        alone = train(keys[i])
        for a, b in zip(
            jax.tree.leaves(alone),
            jax.tree.leaves(jax.tree.map(lambda x: x[i], batched)),
            strict=True,
        ):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-4, atol=1e-5)
    # two seeds, two datasets (the control)
    assert not np.allclose(batched[0].mean[0], batched[0].mean[1])


def test_stacked_pictures_repeat_an_episodes_first():
    # one env, 5 steps; an episode starts at step 0 and another at step 3; picture t is filled
    # with t
    frames = jnp.broadcast_to(
        jnp.arange(5, dtype=jnp.uint8)[:, None, None, None, None], (5, 1, 2, 2, 3)
    )
    data = generators.Rollouts(
        frames, jnp.array([[0], [1], [2], [0], [1]], jnp.int32), jnp.zeros((5, 1, 1))
    )
    stacks = generators.stack_frames(data, jnp.arange(5), jnp.zeros(5, jnp.int32), 3)[..., 0, 0, 0]
    assert stacks.tolist() == [[0, 0, 0], [0, 0, 1], [0, 1, 2], [3, 3, 3], [3, 3, 4]]


def test_the_env_carrying_pictures_keeps_the_tasks_dynamics(tiny_generator):
    gen, params = hint_sources.load(tiny_generator)
    inner = envs.make("dot", "position", ("pixels", "state"))
    framed = hint_sources.GeneratedHintEnv(
        envs.make("dot", "position", ("pixels",)), gen, ("pixels", "state", "hint")
    )
    task = envs.make_params("dot")
    both = hint_sources.GeneratedParams(task, params)
    key = jax.random.key(3)
    a, b = inner.reset(key, task), framed.reset(key, both)
    assert np.array_equal(b.state.frames, np.stack([a.obs["pixels"]] * gen.frames))
    for t in range(inner.max_steps):
        k = jax.random.fold_in(key, t)
        action = jnp.array([np.sin(t)], jnp.float32)
        before = b.state.frames
        a, b = inner.step(k, a.state, action, task), framed.step(k, b.state, action, both)
        assert float(a.reward) == float(b.reward) and bool(a.truncated) == bool(b.truncated)
        assert np.array_equal(a.obs["state"], b.obs["state"]) and np.array_equal(
            a.obs["pixels"], b.obs["pixels"]
        )
        assert np.array_equal(b.state.frames[:-1], before[1:]) and np.array_equal(
            b.state.frames[-1], a.obs["pixels"]
        )
        np.testing.assert_allclose(b.obs["hint"], gen.predict(params, b.state.frames), rtol=1e-6)
    assert bool(b.truncated)


@pytest.fixture(scope="module")
def tiny_generator(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("generators")
    argv = [f"{k}={v}" for k, v in TINY.items()] + [
        "frames=2",
        "seeds=2",
        f"out_dir={out}",
        "name=tiny",
    ]
    assert generator.main(argv) == 0
    return out / "tiny"


@pytest.fixture(scope="module")
def constant_generator(tiny_generator, tmp_path_factory) -> Path:
    """The tiny generator with its network's weights zeroed and its mean set: it says CONSTANT."""
    folder = tmp_path_factory.mktemp("constant")
    cfg = generators.GeneratorConfig(frames=2, seeds=1, **TINY)
    _, params = hint_sources.load(tiny_generator)
    params = jax.tree.map(
        lambda x: x[None],
        params.replace(net=jax.tree.map(jnp.zeros_like, params.net), mean=jnp.full((1,), CONSTANT)),
    )
    blank = jnp.zeros((1, 1))
    generators.write_folder(
        folder, cfg, params, generators.GeneratorMetrics(blank, *[jnp.zeros((1, 1))] * 4), {}
    )
    return folder


def test_the_cli_writes_a_folder_that_loads(tiny_generator):
    meta = json.loads((tiny_generator / hint_sources.GENERATOR_JSON).read_text())
    assert (meta["env"], meta["hint"], meta["frames"], meta["seeds"], meta["dimensions"]) == (
        "dot",
        "position",
        2,
        2,
        ["position"],
    )
    rows = (tiny_generator / "metrics.csv").read_text().splitlines()
    assert (
        rows[0].startswith("seed,dimension,train_mse,heldout_mse,train_r2,heldout_r2")
        and len(rows) == 3
    )
    gen, params = hint_sources.load(tiny_generator, seed=1)
    assert gen == hint_sources.Generator("dot", "position", 2, 16) and params.mean.shape == (1,)


def test_the_agent_sees_only_the_generators_hint(constant_generator):
    cfg = run_config(
        {
            "env": "dot",
            "agent": "hints",
            "hint_source": str(constant_generator),
            "seeds": 1,
            "ppo": TINY_PPO,
        }
    )

    def rollout_hints(cfg):  # jitted: op by op, the init and the rollout took 26 s on 2 cores
        parts = ppo.make_ppo(cfg)
        return np.asarray(
            jax.jit(lambda k: parts.rollout(parts.init(k), k)[1].obs["hint"])(jax.random.key(0))
        )

    assert np.all(rollout_hints(cfg) == CONSTANT)  # the programmatic hint is in [-1, 1]
    # the control: the same rollout without it
    assert np.all(
        np.abs(rollout_hints(dataclasses.replace(cfg, hint_source=hint_sources.PROGRAMMATIC)))
        <= 1.0
    )
    # at deploy: eval_hint_source alone switches the evaluation env's hint
    deployed = dataclasses.replace(
        cfg, hint_source=hint_sources.PROGRAMMATIC, eval_hint_source=str(constant_generator)
    )
    for deploy, seen in ((True, lambda h: h == CONSTANT), (False, lambda h: abs(h) <= 1.0)):
        env, task = deployed.make_env(deploy=deploy), deployed.task_params(None, deploy=deploy)
        assert seen(float(jax.jit(env.reset)(jax.random.key(2), task).obs["hint"][0]))


def test_evaluate_deploys_a_trained_agent_with_learned_hints(constant_generator, tmp_path, capsys):
    values = {
        "env": "dot",
        "agent": "hints",
        "seeds": 1,
        "eval_episodes": 2,
        "ppo": TINY_PPO,
        "out_dir": str(tmp_path),
        "name": "agent",
        "compilation_cache": False,
    }
    assert run.main_from_values(values) == 0
    folder = tmp_path / "agent"
    assert (
        evaluate.main([str(folder), "--episodes", "2", "--hint-source", str(constant_generator)])
        == 0
    )
    written = json.loads(
        (folder / f"eval-default-deterministic-2-hints-{constant_generator.name}.json").read_text()
    )
    assert written["hint_source"] == str(constant_generator) and len(written["returns"][0]) == 2
    before = sorted(p.name for p in folder.iterdir())
    assert evaluate.main([str(folder), "--hint-source", str(tmp_path / "missing")]) == 2
    assert sorted(p.name for p in folder.iterdir()) == before
    assert "no generator at" in capsys.readouterr().err


def test_bad_generators_are_one_line_errors(tiny_generator, tmp_path):
    def refused(source: str, **values) -> str:
        with pytest.raises(UsageError) as e:
            run_config({"env": "dot", "agent": "hints", "hint_source": source, **values})
        assert "\n" not in str(e.value)
        return str(e.value)

    assert "no generator at" in refused(str(tmp_path / "missing"))
    assert "generates dot/position, not cue/cue" in refused(
        str(tiny_generator), env="cue", hint="cue"
    )
    assert "applies to agents that see a hint" in refused(str(tiny_generator), agent="ppo_rgb")
    corrupt = tmp_path / "corrupt"
    shutil.copytree(tiny_generator, corrupt)
    for f in (corrupt / hint_sources.PARAMS).rglob("*"):
        if f.is_file() and f.stat().st_size > 1000:
            f.write_bytes(b"\0" * 100)
    assert "corrupt" in refused(str(corrupt))
    out = tmp_path / "runs"
    assert (
        run.main_from_values(
            {"env": "cue", "hint_source": str(tiny_generator), "out_dir": str(out)}
        )
        == 2
    )
    assert not out.exists()  # nothing written
