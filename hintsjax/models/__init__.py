"""The agents and their networks, as pure Flax.

- `agents`: the agents of the paper's Table 1 as registry entries (what each one sees, which
  algorithm trains it);
- `conditioning`: the four schemes lc, ac, fc, mc that join pixels and hint;
- `networks`: the pixel encoder, MLPs, the hint embedding and the actor-critic;
- `normalization`: the running mean and variance of the state (ppo.normalize_state).

It may import envs/ only: nothing here knows about settings, training or files.
"""
