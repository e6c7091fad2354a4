"""A trained agent's episodes: its evaluation, and a video of one episode.

- `evaluator`: all seeds x N episodes in one jitted call, per variant, for a run or a group;
- `recording`: one episode's pictures with the hint drawn beside them, written as a GIF.

It may import envs/, system, models, settings, cli and algorithms; training imports it.
"""
