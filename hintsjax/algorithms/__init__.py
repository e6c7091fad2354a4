"""The training algorithms, each a pure `Trainer` (init, update, run, train) over one run's state.

- `trainer`: the Trainer every algorithm builds; `registry`: the algorithms by name
  (`make_trainer`: an agent's algorithm picks its trainer);
- `ppo`: rollout, GAE, the clipped-surrogate loss, `make_ppo` and `make_trainer`;
- `dagger`, `gail`: the imitation baselines, which learn from an `experts` policy;
- `experts`: exporting a trained expert and loading the packaged ones (hintsjax/experts/);
- `group`: configurations that share shapes trained as one program (PPO vmapped over members).

It may import envs/, system, models, settings and cli; nothing that runs the loop, evaluates or
writes a run folder.
"""
