"""Reproducing the paper's tables: the library under the table scripts of experiments/.

- `sweep`: train a table's runs (grouped, several worker processes, resumable, over GPUs);
- `sweep_settings`: --set KEY=VALUE, the settings every run of a sweep gets;
- `table_script`: the command line every table script shares: it declares a `TableScript` (its
  runs, tables and reports) and calls `table_main`;
- `report`: read finished runs into table cells, statistics (hintsjax.reproduce.stats) and curves;
- `archive`: the committed archive of what the tables need of each finished run
  (experiments/results/runs), and a run read from runs/ or from it;
- `markdown`: markdown tables, and writing a report (or one script's section of a shared one);
- `flag_variants`: one measurement per XLA flag variant, each in a fresh process.

It may import any of hintsjax (training, configs, statistics, the run log); nothing in hintsjax
imports it. A table script in experiments/ declares its runs and rows and calls `table_main`.
The archive is the checkout's experiments/results/runs, so these tools work in a checkout (an
editable install, `make setup`).
"""
