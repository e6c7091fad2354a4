"""Configurations trained in one group (hintsjax.algorithms.group) give what each gives trained
alone.

Agreement is to float32 rounding, not bit for bit: vmapped over the group, XLA computes the
networks' matrix products and convolutions as batched ones and may sum in another order, and
the padded hint axis adds terms that are exact zeros. After 3 updates every parameter agrees to
1e-6; a member compared with another member's lone run differs by far more (the test's control).
"""

from __future__ import annotations

import json
from pathlib import Path

import jax
import numpy as np
import pytest

import cue_env  # noqa: F401  (registers the test env "cue" and its hints cue [1] and cue_pair [2])
import linear_env  # noqa: F401  (registers the test env "linear")
from hintsjax.system import checkpoint
from hintsjax.system.errors import UsageError
from hintsjax.settings.layers import run_config, save_run_config
from hintsjax.algorithms import group, ppo
from hintsjax.algorithms.registry import make_trainer
from hintsjax.training import outputs, pipeline

# The traced-program cache on for this file's runs (tests/conftest.py): nothing here replaces a
# function, so the group resumed after its SIGKILL, and the finished group resumed to evaluate, load
# what `whole_group` traced.
pytestmark = pytest.mark.usefixtures("traced_programs_kept")

UPDATES = 3
TINY_PPO = {
    "total_env_steps": 3 * 64,
    "num_envs": 4,
    "batch_size": 64,
    "minibatch_size": 32,
    "epochs": 2,
}
SEEDS = 2


def cue_cfg(hint: str, scheme: str = "fc", **ppo_values) -> object:
    return run_config(
        {
            "env": "cue",
            "agent": "hints",
            "scheme": scheme,
            "hint": hint,
            "seeds": SEEDS,
            "eval_episodes": 2,
            "checkpoint_every": 2,
            "checkpoint_seconds": 0,
            "ppo": {**TINY_PPO, **ppo_values},
        }
    )


def trained(trainer, cfg) -> object:
    keys = cfg.seed_keys()
    return jax.jit(jax.vmap(lambda s: trainer.run(s, UPDATES)[0]))(
        jax.jit(jax.vmap(trainer.init))(keys)
    )


def arrays(tree) -> list[np.ndarray]:
    return [
        np.asarray(
            jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
        )
        for x in jax.tree.leaves(tree)
    ]


def max_difference(a, b) -> float:
    return max(
        float(np.max(np.abs(x.astype(np.float64) - y.astype(np.float64)), initial=0.0))
        for x, y in zip(arrays(a), arrays(b), strict=True)
    )


# widths 1, 2 and 3; cue_pair sits at positions 1, 2
HINT_GROUP = ("cue", "cue_pair", "cue+cue_pair")


@pytest.fixture(scope="module")
def hint_group():
    cfgs = [cue_cfg(h) for h in HINT_GROUP]
    g = group.make_group(cfgs)
    return (
        g,
        trained(group.make_group_trainer(g), cfgs[0]),
        [trained(ppo.make_trainer(c), c) for c in cfgs],
    )


def test_the_group_env_computes_every_members_hint_once(hint_group):
    g, _, _ = hint_group
    assert g.hint == "cue+cue_pair" and g.takes == ((0,), (1, 2), (0, 1, 2)) and g.width == 3


@pytest.mark.parametrize("k", range(len(HINT_GROUP)))
def test_each_member_of_a_hint_group_trains_as_it_does_alone(hint_group, k):
    g, together, alone = hint_group
    member = group.cell_state(g, together, k)
    assert jax.tree.structure(member) == jax.tree.structure(alone[k])
    assert [x.shape for x in arrays(member)] == [x.shape for x in arrays(alone[k])]
    assert max_difference(member.params, alone[k].params) < 1e-6
    assert max_difference(member.opt_state, alone[k].opt_state) < 1e-6
    assert max_difference(member.obs, alone[k].obs) == 0.0  # the member saw its own hint, exactly
    other = alone[(k + 1) % len(alone)]  # the control: another member's lone run is far off
    assert max_difference(member.params["params"]["actor"], other.params["params"]["actor"]) > 1e-3


def test_the_padded_hint_weights_stay_exactly_zero(hint_group):
    """cue (width 1) is padded to 3: rows 1 and 2 of its first hint layer see zeros, get zero
    gradients, and Adam leaves them (and their moments) at exactly 0 through training."""
    _, together, _ = hint_group
    kernel = np.asarray(
        together.params["params"]["conditioning"]["HintEmbedding_0"]["Dense_0"]["kernel"]
    )
    assert kernel.shape[:3] == (SEEDS, len(HINT_GROUP), 3)
    assert np.all(kernel[:, 0, 1:] == 0.0) and np.all(kernel[:, 0, :1] != 0.0)
    assert np.all(kernel[:, 1, 2:] == 0.0) and np.all(kernel[:, 2] != 0.0)
    moments = [x for x in jax.tree.leaves(together.opt_state) if x.shape == kernel.shape]
    assert moments and all(np.all(np.asarray(m)[:, 0, 1:] == 0.0) for m in moments)


def test_masked_input_pads_the_encoders_hint_channels():
    """Scheme mc feeds the hint as extra picture channels: the first convolution's input
    channels are padded, and a member trains as alone."""
    cfgs = [cue_cfg(h, scheme="mc") for h in ("cue", "cue_pair")]
    g = group.make_group(cfgs)
    together = trained(group.make_group_trainer(g), cfgs[0])
    # the first conv's kernel
    kernel = np.asarray(jax.tree.leaves(together.params["params"]["encoder"])[1])
    assert kernel.shape[-2] == 3 + 2 and np.all(kernel[:, 0, ..., 4, :] == 0.0)
    alone = trained(ppo.make_trainer(cfgs[0]), cfgs[0])
    assert max_difference(group.cell_state(g, together, 0).params, alone.params) < 1e-6


def test_numbers_that_differ_between_members_are_hyper_leaves():
    """PPO-x and PPO-x+N(0,1) (state noise), and one with other learning rates, entropy bonus,
    clip range, discount and reward scale, share one program; each trains as alone."""
    base = {"env": "linear", "seeds": SEEDS, "ppo": TINY_PPO}
    cfgs = [
        run_config({**base, "agent": "ppo_state"}),
        run_config({**base, "agent": "ppo_noisy_state"}),
        run_config(
            {
                **base,
                "agent": "ppo_state",
                "ppo": {
                    **TINY_PPO,
                    "actor_lr": 3e-3,
                    "critic_lr": 1e-4,
                    "ent_coef": 0.1,
                    "clip_eps": 0.1,
                    "gamma": 0.9,
                    "gae_lambda": 0.8,
                    "reward_scale": 0.5,
                },
            }
        ),
    ]
    g = group.make_group(cfgs)
    assert g.hint == "none" and g.width == 0
    together = trained(group.make_group_trainer(g), cfgs[0])
    alone = [trained(ppo.make_trainer(c), c) for c in cfgs]
    for k in range(3):
        assert max_difference(group.cell_state(g, together, k).params, alone[k].params) < 1e-6
    assert (
        max_difference(alone[0].params, alone[1].params) > 1e-3
        and max_difference(alone[0].params, alone[2].params) > 1e-3
    )


def test_configurations_that_cannot_share_a_group_are_named():
    with pytest.raises(UsageError, match="differ in scheme"):
        group.make_group([cue_cfg("cue", "fc"), cue_cfg("cue", "lc")])
    with pytest.raises(UsageError, match=r"differ in .*ppo\.num_envs"):
        group.make_group([cue_cfg("cue"), cue_cfg("cue", num_envs=8)])
    gail = run_config({"env": "pendulum", "agent": "gail"})
    with pytest.raises(UsageError, match="trains alone"):
        group.make_group([gail, run_config({"env": "pendulum", "agent": "ppo_state"})])
    with pytest.raises(UsageError, match="at least one"):
        group.make_group([])


def test_plan_groups_a_table_by_shape():
    labels = [
        "expert_ppo",
        "ppo_rgb",
        "ppo_state",
        "ppo_noisy_state",
        "hints-fc-angular_velocity",
        "hints-fc-composite",
        "hints-lc-composite",
        "hints-fc-state",
        "dagger",
    ]
    cfgs = []
    for label in labels:
        agent, *rest = label.split("-")
        values = {"env": "pendulum", "agent": agent}
        if rest:
            values.update(scheme=rest[0], hint=rest[1])
        cfgs.append(run_config(values))
    named = [[labels[i] for i in members] for members in group.plan(cfgs)]
    assert named == [
        ["expert_ppo"],
        ["ppo_rgb"],
        ["ppo_state", "ppo_noisy_state"],
        ["hints-fc-angular_velocity", "hints-fc-composite", "hints-fc-state"],
        ["hints-lc-composite"],
        ["dagger"],
    ]


def killed_group(folder: Path) -> tuple[list, Path, list[Path]]:
    """A group of two cue-env configurations with its members' folders under `folder`:
    pipeline.train_group's (configs, group folder, member folders)."""
    cfgs = [cue_cfg(h) for h in ("cue", "cue_pair")]
    dirs = [folder / c.label for c in cfgs]
    for d, c in zip(dirs, cfgs):
        d.mkdir(parents=True, exist_ok=True)
        save_run_config(d, c)
    return cfgs, folder / "group", dirs


@pytest.fixture(scope="module")
def whole_group(tmp_path_factory):
    """killed_group's group trained without interruption by pipeline.train_group: (configs, group
    folder, member folders, its results)."""
    cfgs, group_dir, dirs = killed_group(tmp_path_factory.mktemp("whole"))
    return cfgs, group_dir, dirs, pipeline.train_group(cfgs, group_dir, dirs, progress=False)


def test_train_group_writes_each_members_folder_as_its_own_run(whole_group):
    """Each member's folder gets metrics.csv, eval.json and a checkpoint that the member's own
    config restores (so hintsjax.evaluate and hintsjax.video read it as any run's); a second
    call resumes the group at its end and only evaluates."""
    cfgs, group_dir, dirs, results = whole_group
    for d, c, r in zip(dirs, cfgs, results):
        saved = json.loads((d / outputs.EVAL_JSON).read_text())
        assert (
            saved["label"] == c.label and saved["group"] == [x.label for x in cfgs] and saved == r
        )
        rows = (d / "metrics.csv").read_text().splitlines()
        assert len(rows) == 1 + UPDATES * SEEDS
        state, update = checkpoint.restore_latest(d, make_trainer(c).abstract_state())
        assert update == UPDATES and state.obs["hint"].shape[-1] == ppo.hint_width(c)
    again = pipeline.train_group(cfgs, group_dir, dirs, resume=True, progress=False)
    assert [r["evaluations"] for r in again] == [r["evaluations"] for r in results]


def test_one_program_evaluates_every_member_as_its_own_run_would(hint_group):
    """The group's evaluation (its env, each member's hint picked, padded weights in place) gives
    each member's returns as evaluating the member's own params with its own env does."""
    from hintsjax.evaluation.evaluator import evaluate_group, evaluate_variants

    g, together, _ = hint_group
    evaluations, _ = evaluate_group(g, together)
    for k, cfg in enumerate(g.cfgs):
        alone, _ = evaluate_variants(
            cfg, group.cell_state(g, together, k).params, (None,), cfg.eval_episodes, False
        )
        np.testing.assert_allclose(
            evaluations[k][0]["returns"], alone[0]["returns"], rtol=1e-5, atol=1e-6
        )
    assert evaluations[0][0]["returns"] != evaluations[1][0]["returns"]


def test_a_group_killed_with_sigkill_resumes_to_the_uninterrupted_end_bit_for_bit(
    whole_group, tmp_path
):
    """The group trained in a subprocess is killed with SIGKILL once its first checkpoint is
    written (tests/killed_run.py); resumed, every member's final state equals, bit for bit, that
    of the same group trained without interruption (`whole_group`)."""
    import subprocess
    import sys

    killed = subprocess.run(
        [
            sys.executable,
            str(Path(__file__).parent / "killed_run.py"),
            "group",
            str(tmp_path / "killed"),
        ],
        cwd=Path(__file__).parent,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert killed.returncode == -9, killed.stderr[-2000:]
    cfgs, group_dir, dirs = killed_group(tmp_path / "killed")
    assert checkpoint.latest_update(group_dir) == 2
    pipeline.train_group(cfgs, group_dir, dirs, resume=True, progress=False)
    whole_dirs = whole_group[2]
    for cfg, d, w in zip(cfgs, dirs, whole_dirs):
        abstract = make_trainer(cfg).abstract_state()
        for a, b in zip(
            arrays(checkpoint.restore_latest(d, abstract)[0]),
            arrays(checkpoint.restore_latest(w, abstract)[0]),
            strict=True,
        ):
            np.testing.assert_array_equal(a, b)
