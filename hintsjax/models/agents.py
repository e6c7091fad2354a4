"""The agents as registry entries: the paper's Table 1, and the baselines that use the hint's
privileged signal in training only. Each says which inputs it sees, what the hint is to it, and
which algorithm trains it (hintsjax.algorithms.registry: "ppo", "dagger" or "gail")."""

from __future__ import annotations

from dataclasses import dataclass

from hintsjax.envs.hints import NO_HINT


# What the hint is to an agent that has one (AgentSpec.hint_use):
#   input:  the policy's and the critic's input (HINTS: the scheme conditions the picture's
#           features on it);
#   critic: the critic's input only, beside the picture's features (asymmetric actor-critic,
#           Pinto et al. 2018);
#   target: no network's input; the picture's features predict it through a head, an extra loss
#           (UNREAL's auxiliary tasks, Jaderberg et al. 2017).
HINT_USES = ("input", "critic", "target")


@dataclass(frozen=True)
class AgentSpec:
    """What an agent observes and what the hint is to it. `hint_override` fixes its hint (HINTS-x
    always sees the state); `drops_hint` replaces it by zeros with probability ppo.hint_dropout a
    training step, and always at deployment (input dropout of the hint; not Kamienny et al.
    2020's PI-Dropout, docs/results.md)."""

    pixels: bool = False
    state: bool = False
    hint: bool = False
    state_noise: float = 0.0  # std of N(0, s^2) added to the state in training rollouts
    hint_override: str | None = None
    algorithm: str = "ppo"
    hint_use: str = "input"  # one of HINT_USES
    drops_hint: bool = False
    about: str = ""  # one line for --help

    def __post_init__(self) -> None:
        if self.hint_use not in HINT_USES:  # a misspelt one would quietly act as PPO-RGB
            raise ValueError(f"unknown hint_use {self.hint_use!r}; valid: {', '.join(HINT_USES)}")

    @property
    def imitates(self) -> bool:
        """True when the agent learns from a trained expert (hintsjax.expert)."""
        return self.algorithm in ("dagger", "gail")

    @property
    def observe(self) -> tuple[str, ...]:
        """The env observation keys this agent needs."""
        return tuple(
            k
            for k, used in (("pixels", self.pixels), ("state", self.state), ("hint", self.hint))
            if used
        )

    @property
    def conditioned(self) -> bool:
        """True when a conditioning scheme joins pixels and hint."""
        return self.pixels and self.hint and self.hint_use == "input"

    @property
    def deploy_sees(self) -> tuple[str, ...]:
        """The observation keys the agent acts on at deployment: the hint only where it is the
        policy's input and never dropped."""
        hint_kept = self.hint_use == "input" and not self.drops_hint
        return tuple(k for k in self.observe if k != "hint" or hint_kept)

    @property
    def privileged(self) -> tuple[str, ...]:
        """The observation keys seen in training only (zeros at deployment)."""
        return tuple(k for k in self.observe if k not in self.deploy_sees)

    def hint_for(self, hint: str) -> str:
        """The hint the env computes when a run asks for `hint`: none without a hint input, `state`
        for HINTS-x."""
        if not self.hint:
            return NO_HINT
        return self.hint_override or hint

    def label(self, name: str, scheme: str, hint: str) -> str:
        """Short name of agent `name` for tables: name[-scheme][-hint], the parts that vary it."""
        parts = [name]
        if self.conditioned:
            parts.append(scheme)
        if self.hint and not self.hint_override:
            parts.append(hint)
        return "-".join(parts)


# the agent whose trained policy is exported as an env's expert (hintsjax.expert)
EXPERT_AGENT = "expert_ppo"
# The converged references (tier 3): an env's `learners` layer is every other agent's
# (env_defaults).
REFERENCES = (EXPERT_AGENT, "dagger", "gail")
AGENTS: dict[str, AgentSpec] = {
    "ppo_rgb": AgentSpec(pixels=True, about="PPO-RGB: PPO on the pictures"),
    "ppo_state": AgentSpec(state=True, about="PPO-x: PPO on the state"),
    "ppo_noisy_state": AgentSpec(
        state=True, state_noise=1.0, about="PPO-x+N(0,1): the state, noised in training"
    ),
    "hints_blind": AgentSpec(hint=True, about="the hint alone, no pictures"),
    "hints_state": AgentSpec(
        pixels=True, hint=True, hint_override="state", about="HINTS-x: pictures and the state"
    ),
    "hints": AgentSpec(
        pixels=True, hint=True, about="HINTS: pictures conditioned on the hint (scheme=)"
    ),
    # The baselines that use the hint's privileged signal in training only (pictures at deployment);
    # hint=state makes the state their privileged signal.
    "asym_ac": AgentSpec(
        pixels=True,
        hint=True,
        hint_use="critic",
        about="asymmetric actor-critic: the critic sees the hint beside the pictures",
    ),
    "pi_dropout": AgentSpec(
        pixels=True,
        hint=True,
        drops_hint=True,
        # input dropout of the hint, not Kamienny et al.'s PI-Dropout (there the privileged
        # signal sets multiplicative noise on the picture's features): docs/results.md
        about="HINTS with its hint input zeroed (ppo.hint_dropout) in training, always at deploy",
    ),
    "hint_aux": AgentSpec(
        pixels=True,
        hint=True,
        hint_use="target",
        about="PPO-RGB whose features predict the hint, an extra loss (ppo.aux_coef)",
    ),
    # The references. expert_ppo is PPO on the state at the env's expert budget (its TRAINING's
    # `agents` layer); dagger and gail learn from its exported policy.
    EXPERT_AGENT: AgentSpec(state=True, about="the expert: PPO on the state at its own budget"),
    "dagger": AgentSpec(state=True, algorithm="dagger", about="DAgger from the packaged expert"),
    "gail": AgentSpec(
        state=True, algorithm="gail", about="GAIL from the packaged expert's demonstrations"
    ),
}
