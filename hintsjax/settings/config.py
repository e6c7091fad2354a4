"""One run's configuration: the schema (RunConfig and its sections) and its validation.

Choices (env, agent, scheme, hint, variants) are validated against the registries here, so a
bad name fails before anything is built or written, with a one-line message that lists the
valid choices. A config value of `None` means "the env's default" (hintsjax.settings.env_defaults);
the layers that resolve it, and a run folder's config.yaml, are hintsjax.settings.layers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp

from hintsjax import envs
from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.envs.frames import COLOURS, RGB
from hintsjax.system.checks import INT_MAX, require_positive
from hintsjax.system.errors import UsageError
from hintsjax.models.agents import AGENTS, AgentSpec, EXPERT_AGENT
from hintsjax.models.conditioning import SCHEMES
from hintsjax.models.networks import MIN_IMAGE_SIZE
from hintsjax.settings.algorithm_settings import DaggerConfig, GailConfig, PPOConfig
from hintsjax.settings.env_defaults import ENV_DEFAULTS
from hintsjax.settings.fields import setting
from hintsjax.settings.hint_sources import PROGRAMMATIC, check_matches, hinted_env, hinted_params

MAX_IMAGE_SIZE = 256  # image_size's largest: 4x the default's 64, already 16x its pixels
MAX_FRAMES = 8  # frames' largest: each one more picture in every step a rollout keeps
# The PPO settings an expert (and the imitators it trains) keeps: hintsjax.algorithms.experts.Expert
# replays the policy as a ReLU MLP's Gaussian mean with a parameter's std.
EXPERT_POLICY = {"action_head": "gaussian", "activation": "relu", "std_head": "param"}


def unreplayable(ppo: PPOConfig) -> tuple[str, Any, Any] | None:
    """(setting, its value, what an expert keeps) of the first EXPERT_POLICY setting `ppo` sets
    otherwise; None when an expert can replay its policy."""
    for name, kept in EXPERT_POLICY.items():
        if getattr(ppo, name) != kept:
            return name, getattr(ppo, name), kept
    return None


def env_params(env: str, variant: str | None) -> Any:
    """The params of `env`'s `variant` (None: its default); UsageError naming the valid variants."""
    try:
        return envs.make_params(env, variant)
    except ChoiceError as e:
        raise UsageError(str(e)) from None


@dataclass(frozen=True)
class RunConfig:
    """One training run: what to train, on what, for how many seeds, and how to evaluate it."""

    env: str = setting("pendulum", "the task (the choices below)")
    agent: str = setting("hints", "the learner and what it sees (the choices below)")
    scheme: str = setting("fc", "how the hint conditions the picture's features: lc, ac, fc or mc")
    hint: str = setting(
        "composite",
        "a registered hint, a composite, or names joined by '+' (null: the env's)",
        per_env=True,
    )
    variant: str | None = setting(None, "the env's training variant (null: its default)")
    seeds: int = setting(5, "seeds trained side by side")
    seed: int = setting(0, "seed i of the run is PRNGKey(seed + i)")
    eval_episodes: int = setting(50, "episodes a seed in the evaluation after training")
    eval_variants: tuple[str, ...] = setting(
        (), "deploy variants evaluated after training (null: the env's)", per_env=True
    )
    stochastic_eval: bool = setting(
        False, "sample actions in evaluation (null: the env's; the car samples)", per_env=True
    )
    checkpoint_every: int = setting(10, "updates between progress reports and checkpoints")
    checkpoint_seconds: float = setting(
        30.0,
        "at least this long between checkpoints (0: at every report); the "
        "last update is always saved",
    )
    expert: str | None = setting(
        None, "dagger and gail: an exported expert folder (null: the env's packaged one)"
    )
    hints_from: str | None = setting(
        None, "a Python file or module whose register_hint calls add hints", saved_may_lack=True
    )
    hint_source: str = setting(
        "programmatic", "the hints in training: programmatic, or a generator folder"
    )
    eval_hint_source: str | None = setting(
        None, "the hints at deploy (evaluation, videos); null: as hint_source"
    )
    # Resolved when the config is built (layers.run_config), so a run folder keeps what it stepped
    # with.
    physics: str = setting(
        "auto",
        "MJCF envs: auto (warp on an NVIDIA GPU with warp-lang, else jax), jax "
        "(bit-reproducible) or warp",
    )
    warp_capacity: float = setting(
        2.0,
        "physics=warp: contact and constraint buffers, this many times the model's most per world",
    )
    image_size: int | None = setting(
        None,
        "the pictures' side in pixels, 36 to 256 (null: the env's own, 64; the car's 96)",
        saved_may_lack=True,
    )
    frames: int = setting(
        1,
        f"pictures the agent sees at once, 1 to {MAX_FRAMES}: the last ones side by side along the "
        "channels (1: the paper's one picture; Playground's vision PPO stacks 3)",
        saved_may_lack=True,
    )
    colour: str = setting(
        RGB,
        "the pictures the agent sees: rgb, or grey (one channel a picture, the mean of the three, "
        "as Playground's vision PPO sees them)",
        saved_may_lack=True,
    )
    ppo: PPOConfig = field(default_factory=PPOConfig)
    dagger: DaggerConfig = field(default_factory=DaggerConfig)
    gail: GailConfig = field(default_factory=GailConfig)

    @property
    def agent_spec(self) -> AgentSpec:
        return AGENTS[self.agent]

    @property
    def effective_hint(self) -> str:
        """The hint the env computes: none for agents without one, `state` for HINTS-x."""
        return self.agent_spec.hint_for(self.hint)

    @property
    def label(self) -> str:
        """Short name for tables: agent[-scheme][-hint]."""
        return self.agent_spec.label(self.agent, self.scheme, self.hint)

    def seed_keys(self) -> jax.Array:
        """[S] PRNG keys of the run's seeds: seed i is key(seed + i)."""
        return jnp.stack([jax.random.key(self.seed + i) for i in range(self.seeds)])

    def hint_source_for(self, deploy: bool) -> str:
        """The hint source of training, or of deployment (evaluation, videos) with `deploy`."""
        return (self.eval_hint_source or self.hint_source) if deploy else self.hint_source

    def make_env(
        self, observe: tuple[str, ...] | None = None, hint: str | None = None, deploy: bool = False
    ) -> envs.Env:
        """The env the agent acts in (its hint `hint`, default its own, from the hint source of
        training or of deployment); its params are `task_params`'."""
        observe = self.agent_spec.observe if observe is None else observe
        env = hinted_env(
            self.env,
            self.effective_hint if hint is None else hint,
            observe,
            self.hint_source_for(deploy),
            frames=self.frames,
            colour=self.colour,
            physics=self.physics,
            warp_capacity=self.warp_capacity,
            image_size=self.image_size,
        )
        return envs.SquashedActions(env) if self.ppo.action_head == "tanh" else env

    def task_params(self, variant: str | None, deploy: bool = False) -> Any:
        """The params of `make_env(deploy=deploy)`'s env on `variant` (None: the training variant's
        default)."""
        return hinted_params(
            self.env,
            env_params(self.env, variant),
            self.agent_spec.observe,
            self.hint_source_for(deploy),
        )

    def validate(self) -> "RunConfig":
        try:
            choose("env", self.env, envs.REGISTRY)
            choose("agent", self.agent, AGENTS)
            if self.agent_spec.pixels:
                envs.check_drawable(self.env)
            choose("scheme", self.scheme, SCHEMES)
            if self.hint not in (RunConfig.hint, ENV_DEFAULTS.get(self.env, {}).get("hint")):
                # a hint asked for is named right, even where the agent sees none
                envs.make_hint(self.env, self.hint)
            hint = envs.make_hint(self.env, self.effective_hint)
            envs.resolve_physics(self.env, self.physics)
        except (ChoiceError, envs.PhysicsUnavailable) as e:
            raise UsageError(str(e)) from None
        names = [part.name for part in hint.parts]
        twice = sorted({name for name in names if names.count(name) > 1})
        if twice:
            raise UsageError(
                f"hint '{self.hint}' gives {', '.join(twice)} more than once; name each hint once"
            )
        if self.agent_spec.hint and not names:
            raise UsageError(
                f"agent={self.agent} sees a hint, so hint=none leaves it nothing; valid for "
                f"{self.env}: {', '.join(envs.hint_names(self.env))} (or agent=ppo_rgb, which "
                "sees none)"
            )
        if self.hints_from is not None:
            self._check_hint_widths(hint)
        if not 1 <= self.warp_capacity < float("inf"):
            raise UsageError(
                f"warp_capacity must be a number of at least 1, got {self.warp_capacity}"
            )
        self._check_image_size()
        self._check_frames()
        for v in (self.variant, *self.eval_variants):
            env_params(self.env, v)
        self._check_hint_sources()
        require_positive(self, ("seeds", "eval_episodes", "checkpoint_every"))
        if not 0 <= self.seed <= INT_MAX - self.seeds + 1:  # seed i's key is key(seed + i): 32 bits
            raise UsageError(
                f"seed must be 0 to {INT_MAX - self.seeds + 1} (seed + i for each of {self.seeds} "
                f"seeds is a 32-bit key), got {self.seed}"
            )
        if not self.checkpoint_seconds >= 0:  # NaN too
            raise UsageError(f"checkpoint_seconds must be 0 or more, got {self.checkpoint_seconds}")
        for section in SECTIONS:
            getattr(self, section).validate()
        self._check_pixel_settings()
        # an expert's policy drives dagger and gail as experts.Expert: a ReLU MLP's mean, a
        # parameter's std
        odd = unreplayable(self.ppo)
        if odd and (self.agent_spec.imitates or self.agent == EXPERT_AGENT):
            name, value, kept = odd
            raise UsageError(
                f"ppo.{name}={value} is for PPO's learners; {self.agent} keeps ppo.{name}={kept} "
                "(an expert's policy drives dagger and gail as a Gaussian's mean)"
            )
        if self.agent_spec.algorithm == "dagger" and self.dagger.buffer_size < self.ppo.batch_size:
            raise UsageError(
                f"dagger.buffer_size ({self.dagger.buffer_size}) must hold one round, "
                f"ppo.batch_size ({self.ppo.batch_size})"
            )
        return self

    def _check_pixel_settings(self) -> None:
        """UsageError where a PPO setting of the pixel encoder is set for an agent without
        pictures: it would change nothing."""
        if self.agent_spec.pixels:
            return
        pixel_agents = ", ".join(name for name, spec in AGENTS.items() if spec.pixels)
        if self.ppo.critic_encoder != "shared":
            raise UsageError(
                f"ppo.critic_encoder={self.ppo.critic_encoder} gives the critic a pixel encoder "
                f"of its own; agent={self.agent} sees no pictures (pixel agents: {pixel_agents})"
            )
        if self.ppo.pixel_scale != 1.0:
            raise UsageError(
                f"ppo.pixel_scale={self.ppo.pixel_scale} scales the pictures; agent={self.agent} "
                f"sees none (pixel agents: {pixel_agents})"
            )

    def _check_hint_widths(self, hint: envs.Hint) -> None:
        """UsageError naming a hint (of a hint file) that returns another width than it
        registered."""
        env = envs.make(self.env, envs.NO_HINT, ("state",))
        params = env_params(self.env, self.variant)
        state = jax.eval_shape(env.initial_state, jax.random.key(0), params)
        try:
            envs.check_hint_shapes(hint, state, params)
        except envs.HintFileError as e:
            raise UsageError(f"hints_from={self.hints_from}: {e}") from None

    def _check_frames(self) -> None:
        """UsageError where `frames` is no count of pictures or `colour` no colour, or either is
        not the default for an agent that sees no pictures."""
        if (
            isinstance(self.frames, bool)
            or not isinstance(self.frames, int)
            or not 1 <= self.frames <= MAX_FRAMES
        ):
            raise UsageError(
                f"frames must be a whole number of pictures from 1 to {MAX_FRAMES}, got "
                f"{self.frames!r}"
            )
        if self.frames > 1 and not self.agent_spec.pixels:
            raise UsageError(
                f"frames={self.frames} stacks pictures, and agent={self.agent} sees none; leave "
                "frames at 1, or pick an agent that sees pictures"
            )
        try:
            choose("colour", self.colour, dict.fromkeys(COLOURS))
        except ChoiceError as e:
            raise UsageError(str(e)) from None
        if self.colour != RGB and not self.agent_spec.pixels:
            raise UsageError(
                f"colour={self.colour} is the pictures' colour, and agent={self.agent} sees none; "
                f"leave colour at {RGB}, or pick an agent that sees pictures"
            )

    def _check_image_size(self) -> None:
        """UsageError where `image_size` is no side the encoder takes, or one the env cannot
        draw."""
        if self.image_size is None:
            return
        own = envs.REGISTRY[self.env].cls
        if (
            isinstance(self.image_size, bool)
            or not isinstance(self.image_size, int)
            or not MIN_IMAGE_SIZE <= self.image_size <= MAX_IMAGE_SIZE
        ):
            raise UsageError(
                f"image_size must be a whole number of pixels from {MIN_IMAGE_SIZE} (the encoder's "
                f"smallest) to {MAX_IMAGE_SIZE}, or null for the env's own ({own.image_size}); got "
                f"{self.image_size!r}"
            )
        try:
            own.check_image_size(self.image_size)
        except ValueError as e:
            raise UsageError(str(e)) from None
        if self.image_size != own.image_size and any(
            s not in (None, PROGRAMMATIC) for s in (self.hint_source, self.eval_hint_source)
        ):
            raise UsageError(
                f"image_size={self.image_size}: a generator's hints are read off the env's own "
                f"{own.image_size}x{own.image_size} pictures; leave image_size null with "
                "hint_source=<generator folder>"
            )

    def _check_hint_sources(self) -> None:
        for name in ("hint_source", "eval_hint_source"):
            source = getattr(self, name)
            if source in (None, PROGRAMMATIC):
                continue
            if not self.agent_spec.hint:
                raise UsageError(
                    f"{name} applies to agents that see a hint "
                    f"({', '.join(a for a, s in AGENTS.items() if s.hint)}), not {self.agent}"
                )
            check_matches(source, self.env, self.effective_hint)


# RunConfig's nested settings
SECTIONS = {"ppo": PPOConfig, "dagger": DaggerConfig, "gail": GailConfig}


@dataclass(frozen=True)
class CommandSettings:
    """The run command's own settings: where its folder goes and the compile cache; not a run's
    settings, so not saved in its config.yaml (hintsjax.training.request takes them out)."""

    out_dir: str = setting("runs", "the folder run folders are made in")
    name: str | None = setting(None, "the run folder's name (null: env-label-timestamp)")
    resume: str | None = setting(None, "a run folder to go on with from its last checkpoint")
    compilation_cache: bool | str = setting(
        True,
        "persistent XLA cache: $HINTSJAX_COMPILATION_CACHE or "
        "~/.cache/hintsjax/xla, a folder, or false",
    )
