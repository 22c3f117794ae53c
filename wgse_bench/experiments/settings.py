"""The settings of one experiment-grid command, checked once.

:class:`ExperimentSettings` is what ``tools/analysis_tools/run_experiments.py``
builds from its command line (the grid's ``seeds`` and ``epochs`` filling
what it leaves out) and what the planner (:func:`.runner.plan`) and the
report (:func:`.report.report`) read; no library function sees the
command line itself.
"""
import os
from dataclasses import dataclass
from typing import Optional, Tuple

from wgse_mmseg.argument_checks import (ArgumentError, check_flag,
                                        check_integer, check_path, is_integer)
from wgse_mmseg.limits import MAX_EPOCHS, MAX_ITERS, MAX_SEED


def check_schedule(entry: str, epochs: Optional[int],
                   max_iters: Optional[int]) -> int:
    """The length of ``entry``'s schedule, given by exactly one of
    ``epochs`` (at most :data:`MAX_EPOCHS`) and ``max_iters`` (at most
    :data:`MAX_ITERS`); an error naming them otherwise."""
    check_integer(entry, 'epochs', epochs, 1, MAX_EPOCHS, optional=True)
    check_integer(entry, 'max_iters', max_iters, 1, MAX_ITERS, optional=True)
    if (epochs is None) == (max_iters is None):
        raise ValueError(f'{entry}: give exactly one of epochs and '
                         f'max_iters')
    return epochs if max_iters is None else max_iters


@dataclass(frozen=True)
class ExperimentSettings:
    """What one run of a grid trains, where, and what it reports.

    Args:
        grid: the grid file (e.g. ``configs/experiments/grid_cpu.py``).
        data_root: the dataset root every run trains and tests on (a
            Spike-Cityscapes layout); as given, made absolute for the runs.
        work_dir: one sub-directory per entry and seed.
        seeds: the seeds, each run once (a list is kept as a tuple).
        epochs, max_iters: the schedule, exactly one of them (``>= 1``).
        only: shell-style patterns of the entries to run; ``None``: all.
        report_dir: where the report goes; ``None``: ``work_dir``.
        keep_checkpoints: keep each run's checkpoints once it is done.
        benchmark: measure each reported entry once before reporting.
        report_only: train nothing; report the finished runs.
        deployment: a JSON file of ``tools/analysis_tools/
            benchmark_deployment.py`` whose windows per second (torch eager,
            ONNX Runtime) the report adds per entry; ``None``: none.
    """
    grid: str
    data_root: str
    work_dir: str
    seeds: Tuple[int, ...]
    epochs: Optional[int] = None
    max_iters: Optional[int] = None
    only: Optional[Tuple[str, ...]] = None
    report_dir: Optional[str] = None
    keep_checkpoints: bool = False
    benchmark: bool = False
    report_only: bool = False
    deployment: Optional[str] = None

    def __post_init__(self):
        entry = 'ExperimentSettings'
        check_path(entry, 'grid', self.grid, exists='file')
        check_path(entry, 'data_root', self.data_root)
        check_path(entry, 'work_dir', self.work_dir)
        if not (isinstance(self.seeds, (list, tuple)) and self.seeds and
                all(is_integer(seed, 0, MAX_SEED) for seed in self.seeds)):
            raise ArgumentError(entry, 'seeds', f'a non-empty sequence of '
                                f'integers in [0, {MAX_SEED}]', self.seeds)
        check_schedule(entry, self.epochs, self.max_iters)
        if self.only is not None and not (
                isinstance(self.only, (list, tuple)) and self.only and
                all(isinstance(p, str) and p for p in self.only)):
            raise ArgumentError(entry, 'only', 'a non-empty sequence of '
                                'non-empty patterns, or None', self.only)
        check_path(entry, 'report_dir', self.report_dir, optional=True)
        for name in ('keep_checkpoints', 'benchmark', 'report_only'):
            check_flag(entry, name, getattr(self, name))
        check_path(entry, 'deployment', self.deployment, exists='file',
                   optional=True)
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f'ExperimentSettings: seeds must not repeat '
                             f'(a run would count twice), got '
                             f'{list(self.seeds)}')
        normalised = dict(grid=os.fspath(self.grid),
                          data_root=os.fspath(self.data_root),
                          work_dir=os.fspath(self.work_dir),
                          seeds=tuple(self.seeds))
        if self.only is not None:
            normalised['only'] = tuple(self.only)
        if self.report_dir is not None:
            normalised['report_dir'] = os.fspath(self.report_dir)
        if self.deployment is not None:
            normalised['deployment'] = os.fspath(self.deployment)
        for name, value in normalised.items():
            object.__setattr__(self, name, value)

    @property
    def schedule(self) -> str:
        """``'10 epochs'`` or ``'60 iterations'``."""
        return (f'{self.epochs} epochs' if self.max_iters is None else
                f'{self.max_iters} iterations')

    @property
    def report_to(self) -> str:
        """The directory the report goes to."""
        return self.report_dir or self.work_dir
