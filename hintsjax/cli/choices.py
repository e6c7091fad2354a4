"""The names a command line chooses among, written out for the commands' --help: the envs (each
with its hints and variants), the agents and the conditioning schemes, from their registries."""

from __future__ import annotations

from hintsjax import envs
from hintsjax.models.agents import AGENTS
from hintsjax.models.conditioning import SCHEMES
from hintsjax.settings.env_defaults import ENV_DEFAULTS


def env_lines(name: str) -> list[str]:
    """`name`'s hints (its default first) and variants, one line each."""
    default = ENV_DEFAULTS.get(name, {}).get("hint")
    hints = sorted(envs.hint_names(name), key=lambda h: h != default)
    shown = [f"{h} (default)" if h == default else h for h in hints]
    return [
        f"  {name}",
        f"    hints:    {', '.join(shown) or 'none'}",
        f"    variants: {', '.join(envs.variant_names(name))}",
    ]


def text() -> str:
    """Every env with its hints and variants, every agent and scheme, as lines for a --help page."""
    suite = [name for name in envs.REGISTRY.keys() if ":" not in name]
    adapted = [name for name in envs.REGISTRY.keys() if ":" in name]
    lines = [
        "Choices (from the registries):",
        f"agent:  {', '.join(AGENTS)}",
        *(f"  {name:<16}{spec.about}" for name, spec in AGENTS.items()),
        f"scheme: {', '.join(SCHEMES)}",
        f"env:    {', '.join(suite + adapted)}",
        (
            "Each env's hints (hint=<name>, or names joined by '+'; none for no hint) and variants "
            "(variant=, eval_variants=):"
        ),
    ]
    for name in suite:
        lines += env_lines(name)
    lines.append(
        f"  {', '.join(adapted)}: adapted tasks, with generic hints and their own "
        "(docs/playground.md)"
    )
    return "\n".join(lines)
