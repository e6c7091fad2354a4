"""What a run is: the settings schema, its layers, and the env an agent acts in.

- `config`: RunConfig (the schema) and its validation against the registries;
- `layers`: plain values (defaults, the env's, the command line) into a RunConfig, and a run
  folder's config.yaml written and read back;
- `algorithm_settings`: the `ppo`, `dagger` and `gail` sections; `env_defaults`: each env's
  training defaults as layers;
- `hint_sources`: where a hint comes from, programmatic or a learned generator's folder (the
  env that the settings build for an agent).

It may import envs/, system and models; nothing that trains.
"""
