"""experiments/bench.py: its command-line parsing of physics options, and (slow tier) one training
row at a toy size on CPU (its measured timings run on the GPU)."""

from __future__ import annotations

import sys

import mujoco
import pytest

import bench  # experiments/bench.py: experiments/ is on pytest's path (pyproject's pythonpath)


def test_model_options_parse_enums_by_name_and_numbers():
    options = bench.model_options(
        ["integrator=euler", "iterations=1", "tolerance=1e-6", "cone=ELLIPTIC"]
    )
    assert options == {
        "integrator": mujoco.mjtIntegrator.mjINT_EULER,
        "iterations": 1,
        "tolerance": 1e-6,
        "cone": mujoco.mjtCone.mjCONE_ELLIPTIC,
    }


@pytest.mark.parametrize(
    "item, names",
    [("integrater=EULER", "integrator"), ("integrator=RK5", "RK4"), ("iterations", "iterations")],
)
def test_bad_model_options_name_the_valid_ones(item, names):
    with pytest.raises(ValueError, match=names):
        bench.model_options([item])


def test_the_bench_drops_deterministic_ops_where_the_command_would(monkeypatch):
    """As run.py decides it (envs.likely_warp, which the bench asks of every env): under MuJoCo
    Warp where asked, or auto where the machine would give it; not where an env steps with MJX's
    JAX solver. bench.main drops them when bench.drops_determinism says so, before anything
    runs."""
    from hintsjax import envs

    assert bench.drops_determinism(["ant", "humanoid"], envs.WARP)
    assert not bench.drops_determinism(["ant"], envs.JAX)
    monkeypatch.setattr(envs, "auto_likely_warp", lambda name: name == "ant")
    assert bench.drops_determinism(["ant"], envs.AUTO)
    assert not bench.drops_determinism(["ant", "pendulum"], envs.AUTO)

    class Stop(Exception):
        """Raised where main would drop the flags, or go on past the point where it would."""

    def stop(*_):
        raise Stop

    dropped = []
    monkeypatch.setattr(bench.xla_flags, "drop_determinism", lambda: dropped.append(1) or stop())
    monkeypatch.setattr(bench.envs, "resolve_physics", stop)  # the step after the flags
    for physics, expected in ((envs.JAX, []), (envs.WARP, [1])):
        dropped.clear()
        monkeypatch.setattr(sys, "argv", ["bench.py", "--envs", "ant", "--physics", physics])
        with pytest.raises(Stop):
            bench.main()
        assert dropped == expected, physics


def test_the_parts_record_names_its_settings_and_writes_no_nan():
    """--parts --out: a row an env, its parts in ms; no ended-a-step count (no rollout first) is
    null, not NaN, which JSON readers refuse."""
    import argparse
    import json

    from hintsjax.settings.layers import run_config

    cfg = run_config({"env": "pendulum", "agent": "hints", "scheme": "fc", "seeds": 5})
    args = argparse.Namespace(rollout_starts="ended", warm_rollouts=0)
    row = bench.parts_row(cfg, args, {"rollout": 0.0125, "learn": 0.5}, float("nan"))
    assert row["ended_a_step"] is None and row["parts_ms"] == {"rollout": 12.5, "learn": 500.0}
    assert (row["env"], row["seeds"], row["encoder_dtype"]) == ("pendulum", 5, "float32")
    json.loads(json.dumps(row, allow_nan=False))
    assert bench.parts_row(cfg, args, {}, 2.5)["ended_a_step"] == 2.5


def test_warmed_parts_start_where_episodes_end_as_in_a_run():
    """--warm-rollouts: the state rolled on by the untrained policy, and the envs ended a step in
    the last rollout. The pendulum's episodes are truncated at 200 steps: with rollouts of 100,
    none ends in the first, each of 2 seeds x 2 envs once in the second (4 over 100 steps)."""
    import jax
    import numpy as np

    from hintsjax.algorithms.ppo import make_ppo
    from hintsjax.algorithms.registry import make_trainer
    from hintsjax.settings.layers import run_config

    ppo = {"num_envs": 2, "batch_size": 200, "minibatch_size": 100}
    cfg = run_config({"env": "pendulum", "agent": "ppo_state", "seeds": 2, "ppo": ppo})
    state = jax.jit(jax.vmap(make_trainer(cfg).init))(cfg.seed_keys())
    rollout = jax.jit(jax.vmap(make_ppo(cfg).rollout))
    assert bench.warmed(rollout, state, 0, 2)[0] is state
    assert bench.warmed(rollout, state, 1, 2)[1] == 0.0
    after, ended = bench.warmed(rollout, state, 2, 2)
    assert ended == 4 / 100
    # the envs rolled on, the policy untouched
    assert not np.array_equal(after.obs["state"], state.obs["state"])
    assert all(map(np.array_equal, jax.tree.leaves(after.params), jax.tree.leaves(state.params)))


@pytest.mark.slow
def test_a_training_row_says_which_physics_the_run_got():
    """bench_train end to end on CPU, at a toy size: its row records the physics that `auto`
    resolved to (the run's own eval.json value), and rates from both of its timings."""
    row = bench.bench_train(
        "pendulum", 2, 2, {"num_envs": 4, "batch_size": 64, "minibatch_size": 32, "epochs": 1}
    )
    assert row["physics"] == "jax" and row["updates"] == 2
    assert row["env_steps_per_s"] > 0 and row["scan_env_steps_per_s"] > 0
    assert set(row["update_parts_s"]) >= {"rollout", "learn"}


@pytest.mark.slow
def test_the_ray_casters_bench_times_its_three_parts(capsys):
    """experiments/bench_render.py on two ant pictures: a row with each part's milliseconds, the
    pictures a second and the ray-geom tests a second, all positive."""
    import re

    import bench_render

    bench_render.rows("ant", [2], "jax")
    row = capsys.readouterr().out.strip().splitlines()[-1]
    assert row.split()[:4] == ["ant", "2", "pictures", "64x64,"], row
    times = [float(x) for x in re.findall(r"(?:nearest|cast|render) ([\d.]+) ms", row)]
    assert len(times) == 3 and all(t > 0 for t in times), row
    assert re.search(r"; [\d,]+ pictures/s, [\d.]+ G ray-geom tests/s$", row), row
