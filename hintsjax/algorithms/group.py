"""Configurations trained together: one compiled program over (seed, configuration).

The cells of a table that share a network's structure (the same env, observations, scheme and
PPO shapes; see `signature`) form a group. Its members differ in numbers, which are arrays of
their runner state's `Hyper` (learning rates, entropy bonus, state noise, ...), and in their hint:
the group's env computes every member's hint parts side by side, and each member picks its own
out of them, padded with zeros to the widest member's width. A member's params are drawn at its
own hint width, exactly as alone, then padded with zeros along the hint axis; a zero input gives
those padded weights a zero gradient, so Adam never moves them and they stay inert. The group's
`Trainer` is PPO's update vmapped over the members, so `jax.vmap(group_trainer.train)(keys)`
trains K configurations x S seeds in one call, and `cell_state` gives back each member's state as
its own run would hold it (tests/test_group.py: the same params as the member trained alone).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import jax
import jax.numpy as jnp

from hintsjax import envs
from hintsjax.system.errors import UsageError
from hintsjax.settings import fields
from hintsjax.settings.algorithm_settings import PPOConfig
from hintsjax.settings.config import RunConfig
from hintsjax.settings.hint_sources import PROGRAMMATIC
from hintsjax.algorithms import ppo
from hintsjax.algorithms.ppo import Hyper, RunnerState
from hintsjax.algorithms.trainer import Trainer, program_identity

# The PPO settings that fix the shapes of a run's arrays or the structure of its program (those not
# declared `traced`): the members of a group agree on these; every traced one is a Hyper leaf and
# may differ, but whether an optional one is set at all (ppo.target_kl) is the program's structure
# too.
SHAPES = fields.names(PPOConfig, traced=False)
OPTIONAL_TRACED = tuple(
    f.name
    for f in fields.settings_of(PPOConfig)
    if f.metadata[fields.TRACED] and fields.allows_none(f)
)


def signature(cfg: RunConfig) -> dict[str, Any]:
    """What configurations must share to train in one group (a dict, to name what differs)."""
    spec = cfg.agent_spec
    return {
        "env": cfg.env,
        "variant": cfg.variant,
        # the env the group's first member builds, so every member's
        "physics": cfg.physics,
        "warp_capacity": cfg.warp_capacity,
        "image_size": cfg.image_size,
        "frames": cfg.frames,
        "colour": cfg.colour,
        "algorithm": spec.algorithm,
        "observe": spec.observe,
        "hint_use": spec.hint_use,
        "drops_hint": spec.drops_hint,
        "scheme": cfg.scheme if spec.conditioned else None,
        "seeds": cfg.seeds,
        "seed": cfg.seed,
        **{f"ppo.{k}": getattr(cfg.ppo, k) for k in SHAPES},
        **{f"ppo.{k} is set": getattr(cfg.ppo, k) is not None for k in OPTIONAL_TRACED},
    }


def groupable(cfg: RunConfig) -> bool:
    """Whether `cfg` may share a group: PPO's agents with programmatic hints; the imitation agents,
    and agents whose hints come from a learned generator (hintsjax.generator), train alone."""
    return cfg.agent_spec.algorithm == "ppo" and {
        cfg.hint_source_for(False),
        cfg.hint_source_for(True),
    } == {PROGRAMMATIC}


def check_group(cfgs: Sequence[RunConfig]) -> None:
    """UsageError in one line naming what keeps these configurations from one group."""
    if not cfgs:
        raise UsageError("a group needs at least one configuration")
    first = signature(cfgs[0])
    for cfg in cfgs:
        if not groupable(cfg) and len(cfgs) > 1:
            raise UsageError(
                f"{cfg.env}/{cfg.label} trains alone (algorithm {cfg.agent_spec.algorithm}); "
                "only PPO's agents share a group"
            )
        differ = [k for k, v in signature(cfg).items() if v != first[k]]
        if differ:
            raise UsageError(
                f"{cfg.env}/{cfg.label} cannot share a group with {cfgs[0].env}/{cfgs[0].label}: "
                f"they differ in {', '.join(differ)}"
            )


def plan(cfgs: Sequence[RunConfig]) -> list[list[int]]:
    """The indices of `cfgs` partitioned into groups (in order of first appearance)."""
    groups: dict[Any, list[int]] = {}
    for i, cfg in enumerate(cfgs):
        key = repr(sorted(signature(cfg).items())) if groupable(cfg) else ("alone", i)
        groups.setdefault(key, []).append(i)
    return list(groups.values())


def pad_to(tree: Any, shapes: Any) -> Any:
    """Every leaf zero-padded at the end of each axis to the shape of `shapes`' leaf."""
    return jax.tree.map(
        lambda x, s: jnp.pad(x, [(0, t - n) for n, t in zip(x.shape, s.shape)]), tree, shapes
    )


def crop_to(tree: Any, shapes: Any) -> Any:
    """Every leaf cut to the shape of `shapes`' leaf (its first entries of each axis)."""
    return jax.tree.map(lambda x, s: x[tuple(slice(0, n) for n in s.shape)], tree, shapes)


@dataclass(frozen=True)
class Group:
    """Configurations that train together, and where each one's hint sits in the group's env."""

    cfgs: tuple[RunConfig, ...]
    hint: str  # the env's hint: every member's parts, side by side (envs.NO_HINT without hints)
    takes: tuple[tuple[int, ...], ...]  # per member, the positions of its hint in the env's

    @property
    def width(self) -> int:
        """The hint width every member is padded to: the widest member's."""
        return max(len(t) for t in self.takes)

    def hyper(self, k: int) -> Hyper:
        """Member k's numbers, its hint picked from the group's env and padded to the group's
        width."""
        return Hyper.of(self.cfgs[k], self.takes[k], self.width)

    def own_hyper(self, k: int) -> Hyper:
        """Member k's numbers as alone: its hint, in order, at its own width."""
        return Hyper.of(self.cfgs[k])


def make_group(cfgs: Sequence[RunConfig]) -> Group:
    """The group of validated configurations; UsageError naming what differs if they cannot share
    one."""
    cfgs = tuple(cfgs)
    check_group(cfgs)
    hint, takes = envs.hints.side_by_side(cfgs[0].env, [cfg.effective_hint for cfg in cfgs])
    return Group(cfgs, hint, tuple(takes))


def make_group_trainer(group: Group) -> Trainer:
    """A Trainer whose state holds every member ([K, ...] per seed) and whose update is PPO's,
    vmapped over the members. Metrics are [K] per update."""
    cfg = group.cfgs[0]
    base = ppo.make_trainer(cfg, group.hint)
    env_params = cfg.task_params(cfg.variant)
    hypers = [group.hyper(k) for k in range(len(group.cfgs))]

    def init(key: jax.Array) -> RunnerState:
        k_net, k_run, ts = ppo.start_envs(key, base.env, env_params, cfg.ppo.num_envs)
        padded = jax.eval_shape(
            lambda: ppo.start_params(k_net, base.network, ts.obs, hypers[0], group.width)
        )
        states = []
        for member, hyper in zip(group.cfgs, hypers):  # each drawn at its own width, as alone
            params = pad_to(
                ppo.start_params(k_net, base.network, ts.obs, hyper, ppo.hint_width(member)), padded
            )
            opt_state = ppo.make_optimizer(hyper, params, cfg.ppo).init(params)
            states.append(
                RunnerState(
                    params, opt_state, ts.state, ts.obs, k_run, jnp.zeros((), jnp.int32), hyper
                )
            )
        return jax.tree.map(lambda *x: jnp.stack(x), *states)

    cacheable = all(program_identity(member) is not None for member in group.cfgs)
    return Trainer(
        cfg, base.env, base.network, init, jax.vmap(base.update), repr(group) if cacheable else None
    )


def cell_state(group: Group, state: RunnerState, k: int) -> RunnerState:
    """Member k's seed-batched state ([S, ...]) as its own run holds it: params and optimiser state
    cut to its hint width, its hint alone in the observation and its own Hyper; what a run folder's
    checkpoint of that configuration holds (hintsjax.system.checkpoint.restore_latest reads it)."""
    cfg = group.cfgs[k]
    seeds = jax.tree.leaves(state)[0].shape[0]
    own = ppo.make_trainer(cfg)
    alone = jax.eval_shape(jax.vmap(own.init), jax.random.split(jax.random.key(0), seeds))
    member = jax.tree.map(lambda x: x[:, k], state)
    picked = Hyper.of(cfg, group.takes[k])  # its hint's positions in the group's env, its own width
    own_hyper = jax.tree.map(lambda x: jnp.broadcast_to(x, (seeds,) + x.shape), group.own_hyper(k))
    return crop_to(member.replace(obs=ppo.pick_hint(member.obs, picked), hyper=own_hyper), alone)
