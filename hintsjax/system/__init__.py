"""The process, the machine and the disk: what every other part of the learner may use.

- `errors`: bad input as one line (UsageError, exit 2) and the boundary every command keeps;
- `xla_flags`: XLA's flags, set when hintsjax is imported; `devices`: a run's seeds over the
  devices (and processes); `memory`: lower bounds on what a command needs, checked first;
- `paths`: folders and files a command will write, checked first;
- `checkpoint`: orbax save and restore into the abstract state its caller gives;
- `compilation_cache`, `program_cache`: XLA's persistent cache and the traced programs beside it.

It may import envs/ (hintsjax.envs) and nothing else of hintsjax: it takes what it needs as
arguments (an abstract state, a config read through its fields) rather than importing the code
that builds it.
"""
