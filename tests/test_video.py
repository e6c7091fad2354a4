"""The video command: its rollout matches a step-by-step loop, its GIF has one frame per step, bad
input fails."""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import numpy as np
import pytest
import yaml
from PIL import Image

from hintsjax import envs
from hintsjax.system import checkpoint, refusals
from hintsjax.settings.config import RunConfig
from hintsjax.settings.layers import run_config, save_run_config
from hintsjax.algorithms.ppo import make_network
from hintsjax.algorithms.registry import make_trainer
from hintsjax.evaluation.evaluator import eval_keys
from hintsjax.evaluation.recording import (
    Rollout,
    compose_frame,
    hint_labels,
    policy_action,
    rollout,
    step_keys,
)
from hintsjax.training import pipeline
from hintsjax.video import main

STEPS = 20
TINY_HINTS = {
    "env": "pendulum",
    "agent": "hints",
    "hint": "composite",
    "scheme": "fc",
    "seeds": 2,
    "eval_episodes": 2,
    "eval_variants": [],
    "ppo": {
        "total_env_steps": 256,
        "num_envs": 4,
        "batch_size": 64,
        "minibatch_size": 32,
        "epochs": 1,
    },
}


@dataclass
class TinyRun:
    path: Path
    cfg: RunConfig
    params: Any  # seed-batched [S, ...]

    def seed(self, seed: int) -> Any:
        return jax.tree.map(lambda x: x[seed], self.params)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> TinyRun:
    """A run folder as training leaves it (config.yaml, a checkpoint at update 4) for a tiny
    pendulum hints run, with random params of the network's shapes and a zeroed rest of the
    runner state; building it costs no compile. Training it with pipeline.train takes ~100 s on 2
    CPU cores, mostly compiling (the slow test below does)."""
    path = tmp_path_factory.mktemp("video") / "hints"
    path.mkdir()
    cfg = run_config(TINY_HINTS)
    save_run_config(path, cfg)
    abstract = jax.eval_shape(jax.vmap(make_trainer(cfg).init), cfg.seed_keys())
    rng = np.random.default_rng(0)

    def blank(a):
        if jax.dtypes.issubdtype(a.dtype, jax.dtypes.prng_key):
            return jax.random.wrap_key_data(np.zeros((*a.shape, 2), np.uint32))
        return np.zeros(a.shape, a.dtype)

    # [S, ..., fan_in, fan_out] kernels drawn at 1/sqrt(fan_in); biases and log_std 0
    def weights(a):
        fan_in = math.prod(a.shape[1:-1])
        return (
            (rng.normal(size=a.shape) / np.sqrt(fan_in)).astype(a.dtype)
            if len(a.shape) > 2
            else np.zeros(a.shape, a.dtype)
        )

    state = jax.tree.map(blank, abstract).replace(params=jax.tree.map(weights, abstract.params))
    checkpoint.save(path, state, 4)
    return TinyRun(path, cfg, state.params)


def test_rollout_matches_a_step_by_step_loop(tiny_run):
    cfg, params = tiny_run.cfg, tiny_run.seed(1)
    key = eval_keys(cfg)[1]  # what the command uses for --seed 1
    episode = rollout(cfg, params, None, STEPS, key).cut()
    assert episode.frames.shape == (STEPS, 64, 64, 3) and episode.frames.dtype == np.uint8
    assert episode.hints.shape == (STEPS, 2) and episode.valid.all() and not episode.done.any()

    # The same episode, one jitted env.step at a time; the agent observes the picture and the
    # hint of each state, so the step's own observation is what the rollout must have drawn.
    env, task_params = cfg.make_env(), envs.make_params("pendulum")
    network = make_network(cfg, env)
    env_step = jax.jit(
        lambda p, k, state, obs: env.step(k, state, policy_action(network, p, obs), task_params)
    )
    k_reset, k_run = step_keys(key)
    ts = jax.jit(env.reset)(k_reset, task_params)
    rewards, hints, frames = [], [], []
    for t in range(STEPS):
        ts = env_step(params, jax.random.fold_in(k_run, t), ts.state, ts.obs)
        rewards.append(float(ts.reward))
        hints.append(np.asarray(ts.obs["hint"]))
        frames.append(np.asarray(ts.obs["pixels"]))
    np.testing.assert_allclose(episode.rewards.sum(), sum(rewards), rtol=1e-5)
    np.testing.assert_allclose(episode.rewards, rewards, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(episode.hints, np.stack(hints), rtol=1e-5, atol=1e-6)
    assert np.abs(episode.frames.astype(int) - np.stack(frames)).max() <= 1  # the same pictures
    assert len({f.tobytes() for f in frames}) > 1  # the rod moves: a policy acted


def test_a_run_evaluated_with_sampled_actions_is_filmed_with_them(tiny_run):
    """A run with stochastic_eval (the car's default) acts with sampled actions in its video, the
    same ones for the same key; without it, with the policy mean."""
    import dataclasses

    cfg, params = tiny_run.cfg, tiny_run.seed(1)
    key = eval_keys(cfg)[1]
    sampled_cfg = dataclasses.replace(cfg, stochastic_eval=True)
    mean_episode = rollout(cfg, params, None, STEPS, key).cut()
    sampled = [rollout(sampled_cfg, params, None, STEPS, key).cut() for _ in range(2)]
    np.testing.assert_array_equal(sampled[0].rewards, sampled[1].rewards)
    assert not np.allclose(sampled[0].rewards, mean_episode.rewards)


def test_composed_frame_is_the_upscaled_picture_beside_the_panel():
    env = envs.make("pendulum", hint="composite")
    assert hint_labels(env.hint) == ["angular_velocity[0] (rad/s)", "goal_distance[0] (m)"]
    assert hint_labels(envs.make("pendulum", hint="state").hint) == [
        "state[0] (1)",
        "state[1] (1)",
        "state[2] (rad/s)",
    ]
    picture = np.random.default_rng(0).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    frame = compose_frame(
        picture, np.array([1.5, -0.3]), hint_labels(env.hint), step=3, episode_return=-4.2, scale=2
    )
    # a small picture is padded to 176
    assert frame.shape == (176, 128 + 240, 3) and frame.dtype == np.uint8
    np.testing.assert_array_equal(
        frame[:128, :128], np.repeat(np.repeat(picture, 2, axis=0), 2, axis=1)
    )
    assert (frame[128:, :128] == 255).all()


def test_cut_keeps_the_steps_up_to_the_episode_end():
    valid = np.array([True, True, True, False, False])
    episode = Rollout(
        np.zeros((5, 4, 4, 3), np.uint8),
        np.arange(10, dtype=np.float32).reshape(5, 2),
        np.arange(5, dtype=np.float32),
        np.array([False, False, True, False, True]),
        valid,
    ).cut()
    assert episode.frames.shape == (3, 4, 4, 3) and episode.hints.shape == (3, 2)
    np.testing.assert_array_equal(episode.rewards, [0, 1, 2])
    assert episode.done[-1] and episode.valid.all()


def test_command_writes_one_gif_frame_per_step(tiny_run, capsys):
    out = tiny_run.path / "video-swingup-seed1.gif"  # the default path
    assert main([str(tiny_run.path), "--seed", "1", "--steps", str(STEPS)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith(f"{out}: {STEPS} frames, return ") and len(line.splitlines()) == 1
    cfg = tiny_run.cfg
    # compiled once, shared
    expected = rollout(cfg, tiny_run.seed(1), None, STEPS, eval_keys(cfg)[1]).cut().rewards.sum()
    assert f"return {expected:.2f} " in line
    with Image.open(out) as gif:
        assert gif.n_frames == STEPS
        assert gif.size == (64 * 4 + 240, 64 * 4)  # (width, height) at the default scale 4
    assert out.stat().st_size < 200_000


UNWRITABLE = yaml.safe_load((Path(__file__).parent / "data" / "bad_inputs.yaml").read_text())[
    "unwritable"
]


@pytest.mark.parametrize("case", list(UNWRITABLE))
def test_a_gif_the_machine_refuses_to_write_is_one_line_naming_it_not_a_bug(case, tiny_run, capsys):
    """The bad-input table's unwritable cases (`--out /dev/full`: ENOSPC on the first write) on this
    file's tiny run, at its seed 1 and STEPS steps (the rollout compiled for the test above serves):
    exit 1, one line naming the path, no traceback, nothing written into the run folder."""
    command, *args = case.split()
    assert command == "video"
    before = sorted(p.name for p in tiny_run.path.iterdir())
    argv = [a.format(run=tiny_run.path) for a in args] + ["--seed", "1", "--steps", str(STEPS)]
    assert main(argv) == refusals.MACHINE == 1
    err = capsys.readouterr().err
    assert err.strip().splitlines() == ["error: " + UNWRITABLE[case].format(run=tiny_run.path)], err
    assert "Traceback" not in err and sorted(p.name for p in tiny_run.path.iterdir()) == before


def test_bad_input_fails_in_one_line_and_writes_nothing(tiny_run, tmp_path, capsys):
    tiny_run = tiny_run.path
    before = sorted(p.name for p in tiny_run.iterdir())
    cases = {
        ("--seed", "5"): "--seed must be in [0, 2)",
        ("--variant", "nope"): "valid choices: swingto, swingup",
        ("--steps", "0"): "--steps must be positive",
        ("--scale", "100000"): "--scale 100000 cannot fit:",  # frames of 6.4 M pixels a side
    }
    for args, message in cases.items():
        assert main([str(tiny_run), *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: ") and message in err[0], err
    assert sorted(p.name for p in tiny_run.iterdir()) == before

    assert main([str(tmp_path / "missing")]) == 2
    assert "no run folder" in capsys.readouterr().err
    empty = tmp_path / "no_checkpoint"
    empty.mkdir()
    shutil.copy(tiny_run / "config.yaml", empty / "config.yaml")
    assert main([str(empty)]) == 2
    assert "no checkpoint" in capsys.readouterr().err
    assert sorted(p.name for p in empty.iterdir()) == ["config.yaml"]


@pytest.mark.slow
def test_video_of_a_trained_run(tmp_path):
    """End to end on a run that pipeline.train wrote (slow: ~100 s on 2 CPU cores, mostly
    compiling)."""
    cfg = run_config(TINY_HINTS)
    save_run_config(tmp_path, cfg)
    pipeline.train(cfg, tmp_path, progress=False)
    out = tmp_path / "v.gif"
    assert (
        main(
            [
                str(tmp_path),
                "--variant",
                "swingto",
                "--steps",
                str(STEPS),
                "--scale",
                "2",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    with Image.open(out) as gif:
        assert gif.n_frames == STEPS and gif.size == (128 + 240, 176)
