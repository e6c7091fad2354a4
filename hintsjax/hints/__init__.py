"""Tools that study and learn hints: a learned hint generator's training, and hint ranking.

- `generators`: a generator trained by regression on rollouts, written as a folder that a run's
  `hint_source` reads (the source itself is settings.hint_sources, below the settings);
- `ranking`: the information score and the short training probe of candidate hints;
- `rollouts`: the data rollouts (random actions, the expert in some envs) both train on.

It may import everything below the commands: envs/, system, models, settings, cli, algorithms,
evaluation and training.
"""
