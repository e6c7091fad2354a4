"""A run from its command line to its folder: compile, train in chunks, guard, evaluate, record.

- `request`: what a run command asks for, checked before anything is made or compiled;
- `compilation`: the seeds' layout, a trainer's programs compiled for it, and whether they fit;
- `loop`: the training loop (start fresh or from a checkpoint, then chunk by chunk);
- `guards`: the non-finite check on every chunk, MJX-Warp's buffer check;
- `outputs`: the run folder, eval.json and the learning curve;
- `pipeline`: `train` (one run) and `train_group` (configurations trained as one program);
- `runlog`: metrics.csv, TensorBoard and learning-curve plots.

It may import envs/, system, models, settings, cli, algorithms and evaluation.
"""
