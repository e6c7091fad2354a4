"""The agents of the paper's Table 1 as registry entries: which inputs each one sees and which
algorithm trains it (hintsjax.algorithms.registry: "ppo", "dagger" or "gail")."""

from __future__ import annotations

from dataclasses import dataclass

from hintsjax.envs.hints import NO_HINT


@dataclass(frozen=True)
class AgentSpec:
    """What an agent observes. `hint_override` fixes its hint (HINTS-x always sees the state)."""

    pixels: bool = False
    state: bool = False
    hint: bool = False
    state_noise: float = 0.0  # std of N(0, s^2) added to the state in training rollouts
    hint_override: str | None = None
    algorithm: str = "ppo"

    @property
    def imitates(self) -> bool:
        """True when the agent learns from a trained expert (hintsjax.expert)."""
        return self.algorithm in ("dagger", "gail")

    @property
    def observe(self) -> tuple[str, ...]:
        """The env observation keys this agent needs."""
        return tuple(k for k, used in (("pixels", self.pixels), ("state", self.state), ("hint", self.hint)) if used)

    @property
    def conditioned(self) -> bool:
        """True when a conditioning scheme joins pixels and hint."""
        return self.pixels and self.hint

    def hint_for(self, hint: str) -> str:
        """The hint the env computes when a run asks for `hint`: none without a hint input, `state` for HINTS-x."""
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


EXPERT_AGENT = "expert_ppo"  # the agent whose trained policy is exported as an env's expert (hintsjax.expert)
# The converged references (tier 3): an env's `learners` layer is every other agent's (env_defaults).
REFERENCES = (EXPERT_AGENT, "dagger", "gail")
AGENTS: dict[str, AgentSpec] = {
    "ppo_rgb": AgentSpec(pixels=True),
    "ppo_state": AgentSpec(state=True),
    "ppo_noisy_state": AgentSpec(state=True, state_noise=1.0),
    "hints_blind": AgentSpec(hint=True),
    "hints_state": AgentSpec(pixels=True, hint=True, hint_override="state"),
    "hints": AgentSpec(pixels=True, hint=True),
    # The references. expert_ppo is PPO on the state at the env's expert budget (its TRAINING's
    # `agents` layer); dagger and gail learn from its exported policy.
    EXPERT_AGENT: AgentSpec(state=True),
    "dagger": AgentSpec(state=True, algorithm="dagger"),
    "gail": AgentSpec(state=True, algorithm="gail"),
}
