"""What the commands share about their arguments.

- `choices`: the envs (their hints, variants), agents and schemes, from the registries, for --help;
- `arguments`: `key=value` arguments into a settings dataclass (generator, rank);
- `overrides`: the run command's Hydra overrides checked before Hydra sees them (keys, grammar,
  every job of a sweep).

It may import envs/, system, models and settings; the commands (hintsjax/*.py) and the tools
under them use it.
"""
