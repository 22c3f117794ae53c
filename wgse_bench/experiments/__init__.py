"""Experiment grids: train and evaluate configs over seeds, tabulate, plot.

What ``tools/analysis_tools/run_experiments.py`` runs (its docstring has the
command line; docs/benchmark.md the details), one module per job:

- :mod:`.settings`: :class:`ExperimentSettings`, the checked settings of
  one command (grid, data, work dir, seeds, schedule, what to report);
- :mod:`.grid`: a grid's entries (``<model>_<enhancer>``, the model's
  config with ``model.data_preprocessor.enhancer`` overridden) and the
  ``--cfg-options`` of a run;
- :mod:`.runner`: the runs (train with ``tools/train.py``, test with
  ``tools/test.py``, each in its own process, then time batch-1 inference),
  resumed where interrupted and skipped where done; the training loss read
  back from the logs; each entry's benchmark;
- :mod:`.aggregate`: one row per entry over seeds;
- :mod:`.report`: ``results.csv``, ``results.md``, ``accuracy_vs_time.png``
  and ``loss_curves.png``.
"""
from .aggregate import aggregate, loss_change
from .grid import (ENHANCER_KEY, PROJECT_ROOT, Entry, as_cli, describe,
                   enhancer_options, load_grid, schedule_options, select)
from .report import (CSV_COLUMNS, LOSS_PLOT, plot, plot_loss_curves,
                     read_deployment, report, write_csv, write_markdown)
from .runner import (METRICS, Run, RunFailed, StaleRunError, benchmark_entry,
                     finished, loss_curve, plan, read_benchmark,
                     run_directory, run_one)
from .settings import ExperimentSettings, check_schedule

__all__ = [
    'ExperimentSettings', 'load_grid', 'select', 'StaleRunError', 'plan',
    'finished', 'run_one', 'benchmark_entry', 'aggregate', 'loss_change',
    'report'
]
