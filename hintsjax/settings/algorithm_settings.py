"""Each training algorithm's settings: PPO's, DAgger's and GAIL's, the `ppo`, `dagger` and `gail`
sections of a RunConfig (hintsjax.settings.config). Per-env values over these defaults live beside
each env (hintsjax.settings.env_defaults)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from hintsjax.models.networks import ACTIVATIONS, ENCODERS, STD_HEADS
from hintsjax.system.checks import require_positive, require_range
from hintsjax.system.errors import UsageError
from hintsjax.settings.fields import check_choices, setting


# The policy's action distribution (`ppo.action_head`; the car's learning measurements, issue 26):
#   gaussian: N(mean, std), mean linear in the features, std learnt and state-independent; the env
#             clips the action into its range (so on the car half the gas and brake draws are 0);
#   tanh:     the same Gaussian, its draw squashed into the env's action range
#             (envs.SquashedActions); the entropy bonus is the Gaussian's, before the squash,
#             unless ppo.squashed_entropy (the squashed action's, as Brax's);
#   sigmoid:  the authors' head: mean = 2 sigmoid(x) - 1 in [-1, 1], std floored at 0.01; clipped
#             as gaussian.
ACTION_HEADS = ("gaussian", "tanh", "sigmoid")
# How max_grad_norm clips (hintsjax.algorithms.ppo.make_optimizer): "global", the norm of every
# part's gradient together (a large critic loss then shrinks the actor's step as well); "per_part",
# the encoder's, the actor's and the critic's each alone (and a critic's own encoder's,
# ppo.critic_encoder=own).
GRAD_CLIPS = ("global", "per_part")
# The pixel encoder's arithmetic (`ppo.encoder_dtype`): its convolutions' inputs, weights and
# products; the parameters, the heads and the losses stay float32.
ENCODER_DTYPES = ("float32", "bfloat16")
# Whose encoder the critic reads (`ppo.critic_encoder`): "shared", the actor's (the paper's, and
# CleanRL's and Stable-Baselines3's default), or "own", one of its own that the critic's loss
# alone trains (Brax's vision PPO: a CNN in the policy network and one in the value network).
CRITIC_ENCODERS = ("shared", "own")


@dataclass(frozen=True)
class PPOConfig:
    """PPO settings (SPEC section 5). The budget is counted in environment steps."""

    total_env_steps: int = setting(200_000, "the budget: env steps a seed")
    num_envs: int = setting(
        16, "envs stepped side by side, a speed choice: it does not change the budget"
    )
    batch_size: int = setting(1024, "transitions an update: num_envs x the rollout's length")
    epochs: int = setting(8, "passes over an update's batch")
    minibatch_size: int = setting(256, "transitions a gradient step")
    gamma: float = setting(0.99, "the discount", traced=True)
    gae_lambda: float = setting(0.95, "GAE's lambda", traced=True)
    clip_eps: float = setting(0.2, "the policy ratio's clip", traced=True)
    vf_coef: float = setting(0.5, "the value loss's weight", traced=True)
    ent_coef: float = setting(0.01, "the entropy bonus's weight", traced=True)
    max_grad_norm: float = setting(
        0.5, "the gradient's norm is clipped to this (ppo.grad_clip says whose)", traced=True
    )
    encoder_lr: float = setting(
        1e-3, "Adam's rate for the encoder and the hint's conditioning", traced=True
    )
    actor_lr: float = setting(3e-4, "Adam's rate for the policy's head", traced=True)
    critic_lr: float = setting(1e-3, "Adam's rate for the value head", traced=True)
    hint_width: int = setting(
        64, "the width the hint is embedded to before it conditions the features"
    )
    hidden: tuple[int, ...] = setting((256, 256), "the actor's and critic's hidden layer widths")
    reward_scale: float = setting(
        1.0, "rewards are multiplied by this for learning (not for logging)", traced=True
    )
    # For envs whose reset is dear (the car's track is 800 sequential trace steps): AutoReset.step's
    # `fresh`.
    starts_per_rollout: bool = setting(
        False, "each env's next episode start is drawn once a rollout, not at every reset"
    )
    # As Stable-Baselines3's target_kl; None: off (Table 5 has none).
    target_kl: float | None = setting(
        None,
        "KL early stop: no more steps in an update once a minibatch's approx. KL "
        "from the rollout policy exceeds 1.5 x this (null: off)",
        traced=True,
    )
    normalize_state: bool = setting(
        False,
        "state agents (the state alone as input): normalise the state by its running mean and "
        "std; hints, the state hint too, enter as generated",
    )
    action_head: str = setting(
        "gaussian",
        "the policy's action distribution: gaussian (clipped by the env), tanh "
        "(squashed into the action range) or sigmoid (the authors')",
        choices=ACTION_HEADS,
    )
    # An entropy bonus on the Gaussian before the squash grows with the std without bound, the
    # squashed action's is at most log 2 a dimension (hintsjax.algorithms.ppo_math).
    squashed_entropy: bool = setting(
        False,
        "action_head=tanh: the entropy bonus is the squashed action's (bounded, as Brax's), "
        "not the Gaussian's before the squash",
        saved_may_lack=True,
    )
    grad_clip: str = setting(
        "global",
        "global: max_grad_norm over every part's gradient together; per_part: the "
        "encoder's, actor's and critic's (and a critic's own encoder's) each alone",
        choices=GRAD_CLIPS,
        saved_may_lack=True,
    )
    adam_eps: float = setting(
        1e-5,
        "Adam's epsilon (optax's default is 1e-8; CleanRL's PPO and ours 1e-5)",
        saved_may_lack=True,
    )
    gae_segment: int = setting(
        0,
        "0: GAE over the whole rollout; L: over segments of L steps, each bootstrapped from "
        "the value after it (Brax's unrolls)",
        saved_may_lack=True,
    )
    normalize_before_learning: bool = setting(
        False,
        "normalize_state: merge a rollout's states into the statistics "
        "before learning on it (Brax's order), not after",
        saved_may_lack=True,
    )
    # The ant's KL storms, experiments/results/locomotion_ppo_stability.md.
    critic_trains_encoder: bool = setting(
        True,
        "false: the critic reads the features it shares with the actor "
        "through a stop-gradient, so only the policy's loss moves them",
        saved_may_lack=True,
    )
    # hintsjax/algorithms/kl_rate.py: divided by 1.5 while a minibatch's approx. KL is above 1.5 x
    # target_kl (the KL stop's bound), multiplied by 1.5 (up to 1) while below 0.5 x.
    kl_adaptive_lr: bool = setting(
        False,
        "scale the learning rates by the steps' KL against target_kl (rsl_rl's "
        "adaptive schedule, shrink-only; needs target_kl)",
        saved_may_lack=True,
    )
    # A batch then holds its episodes' first T steps only; an episode cut by the rollout's end is
    # bootstrapped from its value, as any continuing one.
    reset_every_update: bool = setting(
        False,
        "every env starts a fresh episode at each rollout's start (Brax's "
        "resets as Playground's DM Control settings give them)",
        saved_may_lack=True,
    )
    # Bears on the KL storms of experiments/results/locomotion_ppo_stability.md: a std that
    # collapses makes the ratio of the next update's steps explode.
    min_log_std: float | None = setting(
        None,
        "a floor on the policy's log std (Brax's networks floor the std at "
        "0.001, log -6.9); null: none",
        saved_may_lack=True,
    )
    encoder: str = setting(
        "nature",
        "the policy's pixel encoder: nature (the paper's three convolutions) or brax_vision "
        "(Brax's vision PPO's, as Playground tunes it)",
        choices=tuple(ENCODERS),
        saved_may_lack=True,
    )
    encoder_dtype: str = setting(
        "float32",
        "the pixel encoder's arithmetic: float32, or bfloat16 (its parameters stay float32)",
        choices=ENCODER_DTYPES,
        saved_may_lack=True,
    )
    critic_encoder: str = setting(
        "shared",
        "pixel agents: shared, the critic reads the actor's encoder; own, an encoder (and "
        "hint conditioning) of its own, trained by the critic's loss alone at ppo.encoder_lr",
        choices=CRITIC_ENCODERS,
        saved_may_lack=True,
    )
    pixel_scale: float = setting(
        1.0,
        "pixel agents: the pictures enter the encoder in [-pixel_scale, pixel_scale] (bytes / "
        "127.5 - 1, times it; Playground's vision tasks show grey in [-0.5, 0.5])",
        saved_may_lack=True,
    )
    activation: str = setting(
        "relu",
        "the MLPs' hidden activation (actor, critic, hint_aux's hint head): relu, or swish "
        "(Brax's)",
        choices=tuple(ACTIVATIONS),
        saved_may_lack=True,
    )
    std_head: str = setting(
        "param",
        "the policy's std: param, a learnt parameter a dimension whatever the input; softplus, "
        "Brax's: softplus of actor outputs + 0.001, so it depends on the input",
        choices=STD_HEADS,
        saved_may_lack=True,
    )
    # Brax's bootstrap_on_timeout (off in its train()'s defaults and Playground's configs).
    bootstrap_truncated: bool = setting(
        True,
        "a step the time limit cut is bootstrapped from its final observation's value; false: "
        "its advantage is 0 (before the minibatch's normalisation) and its target its own value "
        "(Brax's default)",
        saved_may_lack=True,
    )
    # The privileged-signal baselines (hintsjax/models/agents.py). Shapes, not traced: a Hyper leaf
    # more would keep the checkpoints saved before it from restoring.
    hint_dropout: float = setting(
        0.5,
        "pi_dropout: the chance that a training step's hint is replaced by zeros "
        "(at deployment it always is)",
        saved_may_lack=True,
    )
    aux_coef: float = setting(
        1.0,
        "hint_aux: the weight of the hint's regression loss (mean squared error in the "
        "hint's units)",
        saved_may_lack=True,
    )

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
        require_positive(
            self,
            ("total_env_steps", "num_envs", "batch_size", "epochs", "minibatch_size", "hint_width"),
            "ppo.",
        )
        if self.batch_size % self.num_envs:
            raise UsageError(
                f"ppo.batch_size ({self.batch_size}) must be a multiple of ppo.num_envs "
                f"({self.num_envs})"
            )
        if self.batch_size % self.minibatch_size:
            raise UsageError(
                f"ppo.batch_size ({self.batch_size}) must be a multiple of ppo.minibatch_size "
                f"({self.minibatch_size})"
            )
        if self.total_env_steps < self.batch_size:
            raise UsageError(
                f"ppo.total_env_steps ({self.total_env_steps}) is less than one update's batch "
                f"({self.batch_size})"
            )
        require_positive(
            self,
            (
                "hidden",
                "encoder_lr",
                "actor_lr",
                "critic_lr",
                "max_grad_norm",
                "clip_eps",
                "reward_scale",
            ),
            "ppo.",
        )
        require_range(
            self,
            {
                "gamma": (0.0, 1.0),
                "gae_lambda": (0.0, 1.0),
                "vf_coef": (0.0, math.inf),
                "ent_coef": (0.0, math.inf),
                "hint_dropout": (0.0, 1.0),
                "aux_coef": (0.0, math.inf),
            },
            "ppo.",
        )
        check_choices(self, "ppo.")
        if not self.adam_eps > 0:
            raise UsageError(f"ppo.adam_eps ({self.adam_eps}) must be positive")
        if self.gae_segment < 0 or (self.gae_segment and self.rollout_length % self.gae_segment):
            raise UsageError(
                f"ppo.gae_segment ({self.gae_segment}) must be 0 or divide the rollout length "
                f"({self.rollout_length} = batch_size / num_envs)"
            )
        if not (math.isfinite(self.pixel_scale) and self.pixel_scale > 0):
            raise UsageError(
                f"ppo.pixel_scale must be a positive finite number, got {self.pixel_scale}"
            )
        if self.min_log_std is not None and not math.isfinite(self.min_log_std):
            raise UsageError(
                "ppo.min_log_std must be a finite number, or null for no floor, got "
                f"{self.min_log_std}"
            )
        if self.target_kl is not None and not self.target_kl > 0:
            raise UsageError(
                f"ppo.target_kl ({self.target_kl}) must be positive, or null for no KL early stop"
            )
        if self.squashed_entropy and self.action_head != "tanh":
            raise UsageError(
                f"ppo.squashed_entropy is the entropy of ppo.action_head=tanh's squashed action; "
                f"ppo.action_head={self.action_head} squashes nothing: set ppo.action_head=tanh, "
                "or ppo.squashed_entropy=false"
            )
        if self.critic_encoder == "own" and not self.critic_trains_encoder:
            raise UsageError(
                "ppo.critic_encoder=own gives the critic an encoder that its loss alone trains; "
                "ppo.critic_trains_encoder=false would leave it untrained: drop one of the two"
            )
        if self.kl_adaptive_lr and self.target_kl is None:
            raise UsageError(
                "ppo.kl_adaptive_lr needs ppo.target_kl (the KL it steers the rates to): set "
                "ppo.target_kl, or ppo.kl_adaptive_lr=false"
            )


@dataclass(frozen=True)
class DaggerConfig:
    """DAgger (Ross et al. 2011). Each round rolls out ppo.batch_size steps (ppo.num_envs envs)
    with the beta-mixture of expert and student, labels every visited state with the expert's
    action, adds them to the aggregated dataset and regresses the student on it."""

    beta_decay: float = setting(0.5, "beta_i = beta_decay ** i: round 0 acts as the expert alone")
    buffer_size: int = setting(
        200_000, "the aggregated dataset's capacity; the oldest rows go first when full"
    )
    grad_steps: int = setting(
        32, "student minibatch steps a round (minibatches of ppo.minibatch_size)"
    )
    lr: float = setting(1e-3, "the student's Adam rate")

    def validate(self) -> None:
        if not 0.0 <= self.beta_decay <= 1.0:
            raise UsageError(f"dagger.beta_decay must be in [0, 1], got {self.beta_decay}")
        require_positive(self, ("buffer_size", "grad_steps", "lr"), "dagger.")


GAIL_REWARDS = ("logit", "original")


@dataclass(frozen=True)
class GailConfig:
    """GAIL (Ho and Ermon 2016): PPO on the reward of a discriminator D(s, a) trained to tell
    the expert's (state, action) pairs from the policy's."""

    demonstrations: int = setting(16, "expert episodes, rolled out once at the start of training")
    disc_hidden: tuple[int, ...] = setting((256, 256), "the discriminator's hidden layer widths")
    disc_lr: float = setting(3e-4, "the discriminator's Adam rate")
    disc_steps: int = setting(
        4, "discriminator minibatch steps a PPO update (minibatches of ppo.minibatch_size)"
    )
    # "logit" is mostly negative while the discriminator wins, so ending an episode early pays
    # (idp's agents learn to fall); "original" pays for every step alive (an agent then avoids a
    # task's terminating goal, e.g. acrobot's).
    reward: str = setting(
        "logit",
        "the policy's reward: logit, log D - log(1 - D); original, -log(1 - D) (Ho and Ermon's)",
        choices=GAIL_REWARDS,
    )
    normalize_state: bool = setting(
        False, "D reads the state standardised by the demonstrations' mean and variance"
    )
    grad_penalty: float = setting(
        0.0, "the weight of D's R1 gradient penalty on the expert's pairs"
    )

    def validate(self) -> None:
        require_positive(self, ("demonstrations", "disc_steps", "disc_lr", "disc_hidden"), "gail.")
        if self.grad_penalty < 0:
            raise UsageError(f"gail.grad_penalty must be 0 or more, got {self.grad_penalty}")
        check_choices(self, "gail.")
