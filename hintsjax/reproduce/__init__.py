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

More of what it owns and why: docs/design.md, "Module notes", hintsjax/reproduce/__init__.py.
"""
