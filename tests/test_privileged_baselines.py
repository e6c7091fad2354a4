"""The baselines that use the hint's privileged signal in training only (hintsjax/models/agents.py):
asym_ac (the critic alone sees it), pi_dropout (the policy sees it, dropped at random, and never at
deployment) and hint_aux (the features predict it, an extra loss). Each mechanism is checked where
it could break, and each agent learns what it can on the one-step cue task (tests/cue_env.py),
whose right action only the hint tells."""

from __future__ import annotations

import json
import os

import dot_env  # noqa: F401  registers the "dot" env: its hint is a function of the picture
import cue_env
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_cli import SHIPPED_ENVS
from test_learning import LAST, LEARN_PPO, policy_mean

from hintsjax.models.agents import AGENTS, AgentSpec
from hintsjax.models.networks import ActorCritic
from hintsjax.settings import layers
from hintsjax.algorithms import group, ppo
from hintsjax.cli import overrides
from hintsjax.evaluation import evaluator
from hintsjax import run

OBS = {
    "pixels": jax.random.randint(jax.random.key(1), (4, 36, 36, 3), 0, 255).astype(jnp.uint8),
    "hint": jax.random.normal(jax.random.key(2), (4, 3)),
}


def learn(agent: str, env: str = "cue", **settings):
    cfg = layers.run_config(
        dict(env=env, agent=agent, scheme="fc", seeds=1, ppo={**LEARN_PPO, **settings})
    )
    trainer = ppo.make_trainer(cfg)
    state, metrics = jax.jit(trainer.train)(jax.random.key(0))
    return trainer, state, jax.tree.map(np.asarray, metrics)


def test_the_asymmetric_critic_reads_the_hint_and_the_actor_never_does():
    """asym_ac: the gradient of the actor's outputs with respect to the hint is exactly zero; the
    critic's is not."""
    net = ActorCritic(AGENTS["asym_ac"], "fc", 2)
    params = net.init(jax.random.key(0), OBS)
    assert "critic_hint" in params["params"] and "conditioning" not in params["params"]

    def grad_of(output):
        return jax.grad(lambda h: net.apply(params, {**OBS, "hint": h})[output].sum())(OBS["hint"])

    np.testing.assert_array_equal(grad_of(0), 0.0)  # the action's mean
    # every row's value depends on its hint
    assert np.all(np.abs(np.asarray(grad_of(2))).sum(axis=-1) > 0)


def test_the_hint_is_dropped_at_the_rate_asked_in_training():
    """pi_dropout's training view replaces each env's hint by zeros with probability p (binomial
    bounds, 5 standard deviations over 20000 envs); p = 0 keeps all, p = 1 drops all."""
    cfg = layers.run_config(dict(env="cue", agent="pi_dropout", hint="cue_pair"))
    n, hint, hyper = 20_000, jnp.ones((20_000, 2)), ppo.Hyper.of(cfg)
    for p in (0.0, 0.3, 1.0):
        seen = np.asarray(ppo.observe({"hint": hint}, jax.random.key(7), hyper, drop=p)["hint"])
        dropped = (seen == 0).all(axis=-1)
        assert np.all(dropped | (seen == 1).all(axis=-1))  # a whole hint is dropped or kept
        assert abs(dropped.mean() - p) <= 5 * np.sqrt(p * (1 - p) / n) + 1e-9, (p, dropped.mean())
    # no drop
    np.testing.assert_array_equal(
        ppo.observe({"hint": hint}, jax.random.key(7), hyper)["hint"], hint
    )


def test_only_pi_dropout_rolls_out_with_dropped_hints():
    """In a rollout of the cue task (cues are +-1, so a zero is a drop), pi_dropout's batch has the
    asked share of zero hints, HINTS' none."""
    for agent, p in (("pi_dropout", 0.3), ("hints", 0.0)):
        cfg = layers.run_config(
            dict(env="cue", agent=agent, seeds=1, ppo={**LEARN_PPO, "hint_dropout": 0.3})
        )
        parts = ppo.make_ppo(cfg)
        state = jax.jit(parts.init)(jax.random.key(0))
        _, traj, _ = jax.jit(parts.rollout)(state, jax.random.key(1))
        zeros = float(np.mean(np.asarray(traj.obs["hint"]) == 0))
        assert abs(zeros - p) < 0.1, (agent, zeros)


def test_pi_dropout_reads_the_hint_in_training_and_acts_without_it_at_deployment():
    """Trained with half its hints, its training return beats every blind policy's -1; evaluated,
    where the hint is always dropped, it acts as one blind policy (the same action for both cues)
    and scores about -1 (E[-(a - c)^2] = -(1 + a^2) for a blind action a; 256 episodes' cues average
    near 0), where its policy with the hint in view scores far better."""
    trainer, state, metrics = learn("pi_dropout", hint_dropout=0.5)
    assert metrics["episode_return"][-LAST:].mean() > -0.95, np.round(metrics["episode_return"], 2)
    cues = cue_env.CueState(
        cue=jnp.array([-1.0, 1.0]), t=jnp.zeros(2, jnp.int32), distractor=jnp.zeros(2)
    )
    obs = jax.vmap(trainer.env.observation, in_axes=(0, None))(cues, trainer.env.default_params())
    deployed = trainer.network.apply(state.params, ppo.deploy_view(obs, trainer.cfg.agent_spec))[0]
    assert float(deployed[0, 0]) == float(deployed[1, 0])
    # with the hint it does follow the cue
    low, high = policy_mean(trainer, state.params, [-1.0, 1.0])
    assert low < high, (low, high)
    cfg = trainer.cfg
    params = jax.tree.map(lambda x: x[None], state.params)
    summary = evaluator.evaluate_params(cfg, params, None, 256, False)
    assert summary["mean"] < -0.95, summary["mean"]


@pytest.mark.parametrize("agent", ["asym_ac", "hint_aux"])
def test_the_training_only_baselines_learn_the_best_blind_action(agent):
    """asym_ac and hint_aux act on the picture, which is grey for both cues: they learn toward the
    best blind action (return -1 from -2 at the start, the std falling) and give both cues one
    mean."""
    trainer, state, metrics = learn(agent)
    returns = metrics["episode_return"]
    final = returns[-LAST:].mean()
    assert final > returns[0] + 0.4 and final < -0.7, np.round(returns, 2)
    low, high = policy_mean(trainer, state.params, [-1.0, 1.0])
    assert low == high


def test_hint_aux_learns_to_predict_a_hint_that_the_picture_shows():
    """On the dot task, whose hint (the dot's position) is a function of the picture, hint_aux's
    prediction error falls below 0.02 (the position's variance is 1/3) when the loss is weighted,
    and stays far above it when its weight is 0 (the head then learns nothing)."""
    settings = dict(
        num_envs=32,
        batch_size=256,
        minibatch_size=64,
        epochs=4,
        total_env_steps=3072,
        hidden=[64, 64],
    )
    errors = {
        coef: learn("hint_aux", "dot", **settings, aux_coef=coef)[2]["hint_loss"]
        for coef in (1.0, 0.0)
    }
    assert errors[1.0][-1] < 0.02 and errors[1.0][-1] < errors[1.0][0] / 5, np.round(errors[1.0], 3)
    assert errors[0.0][-LAST:].mean() > 0.05, np.round(errors[0.0], 3)


def test_the_hint_loss_shapes_the_encoder_and_leaves_the_policy_alone():
    """hint_aux: the hint's error reaches every layer of the encoder that the policy shares (what
    makes it an auxiliary task, not a head fitted on fixed features), and none of the actor's or
    the critic's own parameters."""
    net = ActorCritic(AGENTS["hint_aux"], "fc", 3)
    params = net.init(jax.random.key(0), OBS)

    def error(p):
        prediction = net.apply(p, OBS, predict_hint=True)[3]
        return ppo.hint_error(prediction, OBS["hint"], jnp.ones(3, bool))

    grads = jax.grad(error)(params)["params"]
    norms = {
        "/".join(str(getattr(k, "key", k)) for k in path): float(jnp.abs(g).sum())
        for path, g in jax.tree_util.tree_leaves_with_path(grads)
    }
    encoder = {k: v for k, v in norms.items() if k.startswith("encoder/")}
    assert encoder and all(v > 0 for v in encoder.values()), encoder
    assert all(v > 0 for k, v in norms.items() if k.startswith("hint_head/")), norms
    own = {k: v for k, v in norms.items() if k.split("/")[0] in ("actor", "critic", "log_std")}
    assert own and all(v == 0 for v in own.values()), own


def test_the_baselines_train_in_groups_of_their_own():
    """Same observations and scheme, other networks or views: HINTS, pi_dropout, asym_ac and
    hint_aux never share a group; two pi_dropout runs of other rates do not either (hint_dropout is
    a shape)."""
    cfgs = [
        layers.run_config(dict(env="cue", agent=a, ppo=p))
        for a, p in (
            ("hints", {}),
            ("pi_dropout", {}),
            ("asym_ac", {}),
            ("hint_aux", {}),
            ("pi_dropout", {"hint_dropout": 0.2}),
            ("asym_ac", {"ent_coef": 0.02}),
        )
    ]
    assert group.plan(cfgs) == [[0], [1], [2, 5], [3], [4]]


def test_an_agent_says_what_it_sees_at_deployment():
    seen = {name: spec.deploy_sees for name, spec in AGENTS.items()}
    assert seen["hints"] == ("pixels", "hint") and seen["ppo_rgb"] == ("pixels",)
    assert seen["asym_ac"] == seen["pi_dropout"] == seen["hint_aux"] == ("pixels",)
    assert AGENTS["asym_ac"].privileged == ("hint",) and AGENTS["hints"].privileged == ()
    with pytest.raises(ValueError, match="unknown hint_use 'critc'; valid: input, critic, target"):
        AgentSpec(pixels=True, hint=True, hint_use="critc")


TINY_PPO = dict(
    total_env_steps=128, num_envs=4, batch_size=64, minibatch_size=32, epochs=1, hidden=[16]
)


def command_values(out_dir, env: str, agent: str) -> dict:
    """What Hydra gives `python -m hintsjax.run env=<env> agent=<agent>` at a tiny budget."""
    values = overrides.defaults()
    return {
        **values,
        "env": env,
        "agent": agent,
        "seeds": 1,
        "eval_episodes": 2,
        "out_dir": str(out_dir),
        "name": f"{env}-{agent}",
        "compilation_cache": False,
        "ppo": {**values["ppo"], **TINY_PPO},
    }


def train_through_the_command(tmp_path, env: str, agent: str, **more) -> dict:
    image = {} if env == "car_racing" else {"image_size": 36}  # the car draws 96 only
    assert run.main_from_values({**command_values(tmp_path, env, agent), **image, **more}) == 0
    return json.loads((tmp_path / f"{env}-{agent}" / "eval.json").read_text())


# asym_ac in the default tier; the other two (15 and 20 s on 2 cores) in the slow one, beside
# test_a_baseline_trains_on_each_env
@pytest.mark.parametrize(
    "agent",
    ["asym_ac", *(pytest.param(a, marks=pytest.mark.slow) for a in ("pi_dropout", "hint_aux"))],
)
def test_each_baseline_trains_through_the_command_and_says_it_deployed_on_pixels(tmp_path, agent):
    results = train_through_the_command(tmp_path, "pendulum", agent)
    assert results["seen_at_deploy"] == ["pixels"] and np.isfinite(
        results["evaluations"][0]["mean"]
    )


# The slow tier trains one baseline on each other env but the humanoid (the three share everything
# an env gives them: pictures and a hint), the locomotion ones with the state as their signal, as
# privileged_baselines.py does; HINTSJAX_TEST_EVERY_BASELINE=1 trains all three on every shipped env
# (24 runs, 877 s on 2 cores).
EVERY = os.environ.get("HINTSJAX_TEST_EVERY_BASELINE", "") not in ("", "0")
ROTATION = {
    "acrobot": "asym_ac",
    "idp": "pi_dropout",
    "halfcheetah": "hint_aux",
    "ant": "asym_ac",  # the humanoid (pi_dropout, 241 s on 2 cores) with EVERY only
    "car_racing": "hint_aux",
}
CASES = (
    [(env, agent) for env in SHIPPED_ENVS for agent in ("asym_ac", "pi_dropout", "hint_aux")]
    if EVERY
    else list(ROTATION.items())
)


@pytest.mark.slow
@pytest.mark.parametrize("env, agent", CASES)
def test_a_baseline_trains_on_each_env(tmp_path, env, agent):
    hint = {"hint": "state"} if env in ("halfcheetah", "ant", "ant_fast", "humanoid") else {}
    results = train_through_the_command(tmp_path, env, agent, **hint)
    assert results["seen_at_deploy"] == ["pixels"] and np.isfinite(
        results["evaluations"][0]["mean"]
    )


# hint_aux is compared after 1 update: on the cue task's constant pictures its encoder and hint head
# get gradients near 0, which Adam scales up to whole steps, so by update 3 the float rounding of
# the group's padded sums reaches 9e-4 at the default tier's -O0 (none above 1e-7 at XLA's default
# level).
@pytest.mark.slow  # 25 s each on 2 cores: the default tier is near its 10 minutes
@pytest.mark.parametrize("agent, updates", [("asym_ac", 3), ("hint_aux", 1)])
def test_a_baseline_in_a_group_of_hint_widths_trains_as_it_does_alone(agent, updates):
    """asym_ac's critic embedding and hint_aux's head take the group's padded hint: members of
    hint widths 1 and 2 end with their lone runs' params to 1e-6 (the padded weights get zero
    gradients; hint_aux's error counts its own positions only), another member's far off."""
    from test_group import SEEDS, TINY_PPO, max_difference

    cfgs = [
        layers.run_config(
            {"env": "cue", "agent": agent, "hint": h, "seeds": SEEDS, "ppo": TINY_PPO}
        )
        for h in ("cue", "cue_pair")
    ]
    g = group.make_group(cfgs)

    def trained(trainer, cfg):
        return jax.jit(jax.vmap(lambda s: trainer.run(s, updates)[0]))(
            jax.jit(jax.vmap(trainer.init))(cfg.seed_keys())
        )

    together = trained(group.make_group_trainer(g), cfgs[0])
    alone = [trained(ppo.make_trainer(c), c) for c in cfgs]
    for k in range(2):
        member = group.cell_state(g, together, k)
        assert max_difference(member.params, alone[k].params) < 1e-6, (agent, k)
    assert (
        max_difference(
            group.cell_state(g, together, 0).params["params"]["critic"],
            alone[1].params["params"]["critic"],
        )
        > 1e-3
    )


def test_the_hint_error_counts_a_members_own_positions_only():
    """hint_error by hand: errors 1 and 3 on two rows of a width-1 hint, mean 5; padded to width 3
    with any prediction in the padding, the same 5; all positions kept, the padding counts."""
    prediction, hint = jnp.array([[1.0], [3.0]]), jnp.zeros((2, 1))
    assert float(ppo.hint_error(prediction, hint, jnp.array([True]))) == 5.0
    padded = jnp.concatenate([prediction, jnp.full((2, 2), 7.0)], axis=1)
    assert float(ppo.hint_error(padded, jnp.zeros((2, 3)), jnp.array([True, False, False]))) == 5.0
    assert float(ppo.hint_error(padded, jnp.zeros((2, 3)), jnp.ones(3, bool))) == pytest.approx(
        (1 + 9 + 4 * 49) / 6
    )
