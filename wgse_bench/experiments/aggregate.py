"""Aggregation of an experiment grid's finished runs over seeds.

One row per entry (:func:`aggregate`): mean and standard deviation over
seeds of the test metrics, time per image, training time and the training
loss at the end (:func:`loss_change`: how flat the curve had become).
"""
import os.path as osp
import statistics
from typing import Any, Dict, List, Optional, Sequence, Tuple

from wgse_mmseg.fileio.bounded_reads import load_json_file
from wgse_mmseg.limits import LOG_FILE_LIMIT_BYTES

from .grid import Entry, describe
from .runner import METRICS, RESULT, read_benchmark, run_directory


def _quarter(curve: List[List[float]], quarter: int) -> List[float]:
    """The losses of ``curve`` logged in the ``quarter``-th quarter (1 to 4)
    of its iterations, ``(q - 1) / 4 < step / last <= q / 4``."""
    last = curve[-1][0] if curve else 0
    return [loss for step, loss in curve
            if (quarter - 1) * last / 4 < step <= quarter * last / 4]


def loss_change(curve: List[List[float]]) -> Optional[float]:
    """How far the loss still fell at the end of training: the mean logged
    loss over the last quarter of the iterations relative to the quarter
    before, minus one (``-0.05``: still 5 % lower); ``None`` with fewer than
    two points in either quarter."""
    third, fourth = _quarter(curve, 3), _quarter(curve, 4)
    if len(third) < 2 or len(fourth) < 2:
        return None
    return statistics.fmean(fourth) / statistics.fmean(third) - 1


def _mean_std(values: List[float]) -> Tuple[float, Optional[float]]:
    return (statistics.fmean(values),
            statistics.stdev(values) if len(values) > 1 else None)


def aggregate(entries: List[Entry], seeds: Sequence[int],
              work_dir: str) -> List[Dict[str, Any]]:
    """One row per entry with finished runs: mean and standard deviation
    over seeds (``None`` with one seed) of the metrics, ms per image (each
    run's median), training time, the final training loss (the mean logged
    loss over the last quarter of the iterations) and :func:`loss_change`;
    each run's loss curve (``loss_curves``); and the entry's benchmark
    (:func:`.runner.benchmark_entry`; ``None`` where not measured)."""
    rows = []
    for entry in entries:
        results = []
        for seed in seeds:
            path = osp.join(run_directory(work_dir, entry, seed), RESULT)
            if osp.exists(path):
                results.append(load_json_file(path, 'run result',
                                              LOG_FILE_LIMIT_BYTES))
        if not results:
            continue
        row = dict(name=entry.name, model=entry.model,
                   enhancer=describe(entry.enhancer, entry.variant_options),
                   seeds=len(results), params=results[0]['params'],
                   enhancer_params=results[0]['enhancer_params'])
        columns = {m: [r[m] for r in results] for m in METRICS}
        columns['ms_per_image'] = [r['ms_per_image']['median']
                                   for r in results]
        columns['train_seconds'] = [r['train_seconds'] for r in results]
        curves = [r.get('loss_curve') or [] for r in results]
        columns['final_loss'] = [_final_loss(c) for c in curves]
        columns['loss_change'] = [loss_change(c) for c in curves]
        for key, values in columns.items():
            if any(v is None for v in values):
                row[f'{key}_mean'] = row[f'{key}_std'] = None
            else:
                row[f'{key}_mean'], row[f'{key}_std'] = _mean_std(values)
        row['loss_curves'] = curves
        row['benchmark'] = read_benchmark(work_dir, entry)
        row['environment'] = results[0]['environment']
        row['image_size'] = results[0]['image_size']
        rows.append(row)
    return rows


def _final_loss(curve: List[List[float]]) -> Optional[float]:
    """The mean logged loss over the last quarter; ``None`` without a
    curve."""
    fourth = _quarter(curve, 4)
    return statistics.fmean(fourth) if fourth else None
