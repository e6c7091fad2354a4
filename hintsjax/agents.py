"""The agents of the paper's Table 1 as registry entries: which inputs each one sees."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class AgentSpec:
    """What an agent observes. `hint_override` fixes its hint (HINTS-x always sees the state)."""

    pixels: bool = False
    state: bool = False
    hint: bool = False
    state_noise: float = 0.0  # std of N(0, s^2) added to the state in training rollouts
    hint_override: str | None = None

    @property
    def observe(self) -> tuple[str, ...]:
        """The env observation keys this agent needs."""
        return tuple(k for k, used in (("pixels", self.pixels), ("state", self.state), ("hint", self.hint)) if used)

    @property
    def conditioned(self) -> bool:
        """True when a conditioning scheme joins pixels and hint."""
        return self.pixels and self.hint


AGENTS: dict[str, AgentSpec] = {
    "ppo_rgb": AgentSpec(pixels=True),
    "ppo_state": AgentSpec(state=True),
    "ppo_noisy_state": AgentSpec(state=True, state_noise=1.0),
    "hints_blind": AgentSpec(hint=True),
    "hints_state": AgentSpec(pixels=True, hint=True, hint_override="state"),
    "hints": AgentSpec(pixels=True, hint=True),
}
