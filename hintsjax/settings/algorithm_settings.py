"""Each training algorithm's settings: PPO's, DAgger's and GAIL's, the `ppo`, `dagger` and `gail`
sections of a RunConfig (hintsjax.settings.config). Per-env values over these defaults live beside each
env (hintsjax.settings.env_defaults)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from hintsjax.system.errors import UsageError, require_positive, require_range


# The policy's action distribution (`ppo.action_head`; the car's learning measurements, issue 26):
#   gaussian: N(mean, std), mean linear in the features, std learnt and state-independent; the env
#             clips the action into its range (so on the car half the gas and brake draws are 0);
#   tanh:     the same Gaussian, its draw squashed into the env's action range (envs.SquashedActions);
#             the entropy bonus stays the Gaussian's, before the squash (no closed form after it);
#   sigmoid:  the authors' head: mean = 2 sigmoid(x) - 1 in [-1, 1], std floored at 0.01; clipped as gaussian.
ACTION_HEADS = ("gaussian", "tanh", "sigmoid")
# How max_grad_norm clips (hintsjax.algorithms.ppo.make_optimizer): "global", the norm of every part's
# gradient together (a large critic loss then shrinks the actor's step as well); "per_part", the
# encoder's, the actor's and the critic's each alone.
GRAD_CLIPS = ("global", "per_part")


@dataclass(frozen=True)
class PPOConfig:
    """PPO settings (SPEC section 5). The budget is counted in environment steps."""

    total_env_steps: int = 200_000
    num_envs: int = 16  # a speed choice: it does not change the budget (an env's TRAINING may set its own, which wins)
    batch_size: int = 1024  # transitions per update: num_envs * rollout length
    epochs: int = 8
    minibatch_size: int = 256
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_eps: float = 0.2
    vf_coef: float = 0.5
    ent_coef: float = 0.01
    max_grad_norm: float = 0.5
    encoder_lr: float = 1e-3
    actor_lr: float = 3e-4
    critic_lr: float = 1e-3
    hint_width: int = 64
    hidden: tuple[int, ...] = (256, 256)
    reward_scale: float = 1.0  # rewards are multiplied by this for learning (not for logging)
    # Draw each env's next start once per rollout rather than on every step (AutoReset.step's
    # `fresh`): for envs whose reset is dear (the car's track is 800 sequential trace steps).
    starts_per_rollout: bool = False
    # KL early stop (as Stable-Baselines3's target_kl): within an update, once a minibatch's approx.
    # KL from the rollout policy exceeds 1.5 x target_kl, that minibatch and the rest of the
    # update's epochs take no step. None: off (Table 5 has none).
    target_kl: float | None = None
    # State agents: normalise the state by its running mean and std (hintsjax.models.normalization).
    normalize_state: bool = False
    action_head: str = "gaussian"  # one of ACTION_HEADS
    grad_clip: str = "global"  # one of GRAD_CLIPS
    adam_eps: float = 1e-5  # Adam's epsilon (optax's default is 1e-8; CleanRL's PPO and ours 1e-5)
    # GAE's horizon: 0 runs it over the whole rollout; L > 0 cuts the rollout into segments of L
    # steps, each bootstrapped from the value after it, no advantage flowing across (Brax's unrolls).
    gae_segment: int = 0
    # normalize_state: merge each rollout's states into the statistics before learning on it (Brax's
    # order: the first update already learns on normalised states) rather than after (ours: the
    # rollout and the learning on it see the same statistics).
    normalize_before_learning: bool = False
    # Whether the critic's loss trains the features it shares with the actor (the encoder and the
    # hint's conditioning; the paper's agent: true). false: the critic reads them through a
    # stop-gradient, so only the policy's loss moves them (the ant's KL storms,
    # experiments/results/locomotion_ppo_stability.md).
    critic_trains_encoder: bool = True
    # Scale the learning rates by the KL of the steps, rsl_rl's adaptive schedule, shrink-only
    # (hintsjax/algorithms/kl_rate.py): divided by 1.5 while a minibatch's approx. KL is above
    # 2 x target_kl, multiplied by 1.5 (up to 1) while below 0.5 x; needs target_kl.
    kl_adaptive_lr: bool = False
    # Start every env afresh at each rollout's start (Brax's num_resets_per_eval as Playground's
    # DM Control settings give it: a batch then holds its episodes' first T steps only; an episode
    # cut by the rollout's end is bootstrapped from its value, as any continuing one).
    reset_every_update: bool = False

    @property
    def rollout_length(self) -> int:
        return self.batch_size // self.num_envs

    @property
    def num_updates(self) -> int:
        return self.total_env_steps // self.batch_size

    @property
    def num_minibatches(self) -> int:
        return self.batch_size // self.minibatch_size

    def validate(self) -> None:
        require_positive(self, ("total_env_steps", "num_envs", "batch_size", "epochs", "minibatch_size", "hint_width"), "ppo.")
        if self.batch_size % self.num_envs:
            raise UsageError(f"ppo.batch_size ({self.batch_size}) must be a multiple of ppo.num_envs ({self.num_envs})")
        if self.batch_size % self.minibatch_size:
            raise UsageError(
                f"ppo.batch_size ({self.batch_size}) must be a multiple of ppo.minibatch_size ({self.minibatch_size})"
            )
        if self.total_env_steps < self.batch_size:
            raise UsageError(
                f"ppo.total_env_steps ({self.total_env_steps}) is less than one update's batch ({self.batch_size})"
            )
        require_positive(self, ("hidden", "encoder_lr", "actor_lr", "critic_lr", "max_grad_norm", "clip_eps", "reward_scale"),
                         "ppo.")
        require_range(self, {"gamma": (0.0, 1.0), "gae_lambda": (0.0, 1.0), "vf_coef": (0.0, math.inf),
                             "ent_coef": (0.0, math.inf)}, "ppo.")
        if self.action_head not in ACTION_HEADS:
            raise UsageError(f"unknown ppo.action_head {self.action_head!r}; valid: {', '.join(ACTION_HEADS)}")
        if self.grad_clip not in GRAD_CLIPS:
            raise UsageError(f"unknown ppo.grad_clip {self.grad_clip!r}; valid: {', '.join(GRAD_CLIPS)}")
        if not self.adam_eps > 0:
            raise UsageError(f"ppo.adam_eps ({self.adam_eps}) must be positive")
        if self.gae_segment < 0 or (self.gae_segment and self.rollout_length % self.gae_segment):
            raise UsageError(f"ppo.gae_segment ({self.gae_segment}) must be 0 or divide the rollout length "
                             f"({self.rollout_length} = batch_size / num_envs)")
        if self.target_kl is not None and not self.target_kl > 0:
            raise UsageError(f"ppo.target_kl ({self.target_kl}) must be positive, or null for no KL early stop")
        if self.kl_adaptive_lr and self.target_kl is None:
            raise UsageError("ppo.kl_adaptive_lr needs ppo.target_kl (the KL it steers the rates to): set ppo.target_kl, "
                             "or ppo.kl_adaptive_lr=false")


@dataclass(frozen=True)
class DaggerConfig:
    """DAgger (Ross et al. 2011). Each round rolls out ppo.batch_size steps (ppo.num_envs envs)
    with the beta-mixture of expert and student, labels every visited state with the expert's
    action, adds them to the aggregated dataset and regresses the student on it."""

    beta_decay: float = 0.5  # beta_i = beta_decay ** i: round 0 acts as the expert alone
    buffer_size: int = 200_000  # the aggregated dataset's capacity; the oldest rows go first when full
    grad_steps: int = 32  # student minibatch steps per round (minibatches of ppo.minibatch_size)
    lr: float = 1e-3

    def validate(self) -> None:
        if not 0.0 <= self.beta_decay <= 1.0:
            raise UsageError(f"dagger.beta_decay must be in [0, 1], got {self.beta_decay}")
        require_positive(self, ("buffer_size", "grad_steps", "lr"), "dagger.")


GAIL_REWARDS = ("logit", "original")


@dataclass(frozen=True)
class GailConfig:
    """GAIL (Ho and Ermon 2016): PPO on the reward of a discriminator D(s, a) trained to tell
    the expert's (state, action) pairs from the policy's."""

    demonstrations: int = 16  # expert episodes, rolled out once at the start of training
    disc_hidden: tuple[int, ...] = (256, 256)
    disc_lr: float = 3e-4
    disc_steps: int = 4  # discriminator minibatch steps per PPO update (minibatches of ppo.minibatch_size)
    # "logit": log D - log(1 - D), the log odds; mostly negative while the discriminator wins, so
    # ending an episode early pays (idp's agents learn to fall).
    # "original": -log(1 - D) > 0, Ho and Ermon's, which pays for every step alive (an agent
    # then avoids a task's terminating goal, e.g. acrobot's).
    reward: str = "logit"
    # D reads the state standardised by the demonstrations' mean and variance (gail.py).
    normalize_state: bool = False
    grad_penalty: float = 0.0  # weight of D's R1 gradient penalty on the expert's pairs (gail.py)

    def validate(self) -> None:
        require_positive(self, ("demonstrations", "disc_steps", "disc_lr", "disc_hidden"), "gail.")
        if self.grad_penalty < 0:
            raise UsageError(f"gail.grad_penalty must be 0 or more, got {self.grad_penalty}")
        if self.reward not in GAIL_REWARDS:
            raise UsageError(f"unknown gail.reward {self.reward!r}; valid: {', '.join(GAIL_REWARDS)}")

