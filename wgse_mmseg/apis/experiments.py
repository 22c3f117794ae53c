"""Experiment grids: train and evaluate configs over seeds, tabulate, plot.

What ``tools/analysis_tools/run_experiments.py`` runs (its docstring has the
command line). A grid (e.g. ``configs/experiments/grid_cpu.py``) lists
models and enhancers; each entry ``<model>_<enhancer>`` is the model's
config with ``model.data_preprocessor.enhancer`` overridden. Each (entry,
seed) run trains with ``tools/train.py`` and evaluates its final checkpoint
with ``tools/test.py``, each in its own process with the grid's
``--cfg-options``, then times batch-1 inference on a validation-sized
stream. A run is done when ``WORK_DIR/<entry>/seed_<seed>/result.json``
exists (written atomically): re-running skips finished runs and resumes an
interrupted one from its last checkpoint. :func:`report` aggregates every
finished run into ``results.csv``, ``results.md`` and
``accuracy_vs_time.png``. See docs/benchmark.md.
"""
import argparse
import csv
import fnmatch
import glob
import io
import json
import os
import os.path as osp
import shlex
import statistics
import subprocess
import sys
import time
from typing import Any, Dict, List, NamedTuple, Optional, Tuple

from mmengine.config import Config

from .benchmarking import (benchmark_config, markdown_table, run_isolated,
                           validation_cost)
from ..core.arguments import Integer, declare
from ..core.io import atomic_output
from ..core.limits import MAX_EPOCHS, MAX_ITERS

#: where the package keeps its ``configs/`` and ``tools/`` (``setup.py``
#: links them into ``wgse_mmseg/.mim``, MMSeg's convention for mim)
PROJECT_ROOT = osp.join(osp.dirname(osp.dirname(osp.abspath(__file__))),
                        '.mim')
METRICS = ('mIoU', 'mAcc', 'aAcc')
ENHANCER_KEY = 'model.data_preprocessor.enhancer'


class Entry(NamedTuple):
    """One grid entry: a model config with one enhancer in front.

    Further ``--cfg-options`` for training, testing and the benchmark:
    ``model_options``, the model's (e.g. a shallower backbone), then
    ``variant_options``, the enhancer variant's (e.g. its learning rate).
    """
    name: str
    model: str
    config: str
    enhancer_name: str
    enhancer: Optional[dict]
    model_options: Dict[str, Any]
    variant_options: Dict[str, Any]


class RunFailed(RuntimeError):
    """A training or test process of one run exited with an error."""


def _split(path: str, what: str, value: Any, main: str,
           is_main: bool) -> Tuple[Any, Dict[str, Any]]:
    """``(main value, cfg_options)`` of a grid value given either alone or
    as ``dict(<main>=..., cfg_options=dict(...))``."""
    if not (isinstance(value, dict) and not is_main):
        return value, {}
    unknown = set(value) - {main, 'cfg_options'}
    if main not in value or unknown:
        raise ValueError(f'{path}: {what} must be given alone or as '
                         f'dict({main}=..., cfg_options=dict(...)), got '
                         f'{dict(value)!r}')
    options = dict(value.get('cfg_options') or {})
    as_cli(options)  # a clear error now for what the command line can't carry
    return value[main], options


def load_grid(path: str) -> Tuple[Config, List[Entry]]:
    """The grid config and its entries, models outer, enhancers inner.

    A model is a config path, relative to the project root, where
    ``configs/`` is (or absolute), or ``dict(config=PATH,
    cfg_options=dict(...))``. An enhancer is ``None`` (raw spikes), an
    enhancer config (``dict(type=...)``) or ``dict(enhancer=None | dict(
    type=...), cfg_options=dict(...))``: a variant that also changes the
    training recipe.
    """
    grid = Config.fromfile(path)
    for key in ('models', 'enhancers', 'cfg_options', 'epochs', 'seeds',
                'latency'):
        if key not in grid:
            raise ValueError(f'{path}: the grid must define {key!r}')
    entries = []
    for model, value in grid.models.items():
        config, model_options = _split(path, f'model {model!r}', value,
                                       'config', isinstance(value, str))
        config = osp.join(PROJECT_ROOT, config)
        if not osp.isfile(config):
            raise FileNotFoundError(f'{path}: model {model!r}: {config} '
                                    f'does not exist')
        for name, value in grid.enhancers.items():
            enhancer, options = _split(
                path, f'enhancer {name!r}', value, 'enhancer',
                value is None or 'type' in value)
            entries.append(Entry(f'{model}_{name}', model, config, name,
                                 None if enhancer is None else
                                 dict(enhancer), model_options, options))
    return grid, entries


def select(entries: List[Entry], patterns: Optional[List[str]]) -> List[
        Entry]:
    """Entries matching any of the shell-style ``patterns`` (all if none);
    a pattern matching nothing is an error that lists the names."""
    if not patterns:
        return entries
    for pattern in patterns:
        if not any(fnmatch.fnmatchcase(e.name, pattern) for e in entries):
            raise ValueError(f'--only {pattern!r} matches no entry; the '
                             f'grid has: {", ".join(e.name for e in entries)}')
    return [e for e in entries
            if any(fnmatch.fnmatchcase(e.name, p) for p in patterns)]


def enhancer_options(enhancer: Optional[dict]) -> Dict[str, Any]:
    """``--cfg-options`` replacing the enhancer of a raw-spike config."""
    if enhancer is None:
        return {ENHANCER_KEY: None}
    options = {f'{ENHANCER_KEY}._delete_': True}
    options.update({f'{ENHANCER_KEY}.{k}': v for k, v in enhancer.items()})
    return options


@declare(epochs=Integer(1, MAX_EPOCHS, optional=True),
         max_iters=Integer(1, MAX_ITERS, optional=True))
def schedule_options(epochs: Optional[int],
                     max_iters: Optional[int]) -> Tuple[Dict[str, Any], str]:
    """``--cfg-options`` for the schedule and the final checkpoint's name.

    The base schedule's shape is kept: linear warm-up for a tenth of the
    run (at least one epoch or iteration), then polynomial decay to the end
    (a one-epoch run is warm-up only). A checkpoint is kept after every epoch
    (a tenth of the iterations), so an interrupted run resumes; validation
    during training is off (the run is tested afterwards).
    """
    if (epochs is None) == (max_iters is None):
        raise ValueError('give exactly one of epochs and max_iters')
    length = epochs if max_iters is None else max_iters
    warmup = max(1, length // 10)
    options = {
        'val_cfg': None, 'val_dataloader': None, 'val_evaluator': None,
        'param_scheduler.0.end': warmup,
        'param_scheduler.1.begin': warmup,
        'param_scheduler.1.end': max(length, warmup + 1),
        'default_hooks.checkpoint.max_keep_ckpts': 1,
    }
    if max_iters is None:
        options.update({'train_cfg.max_epochs': epochs,
                        'default_hooks.checkpoint.interval': 1})
        return options, f'epoch_{epochs}.pth'
    for index in (0, 1):
        options.update({f'param_scheduler.{index}.by_epoch': False,
                        f'param_scheduler.{index}.convert_to_iter_based':
                        False})
    options.update({
        'train_cfg._delete_': True,
        'train_cfg.type': 'IterBasedTrainLoop',
        'train_cfg.max_iters': max_iters,
        'default_hooks.checkpoint.by_epoch': False,
        'default_hooks.checkpoint.interval': warmup,
        'default_hooks.logger.log_metric_by_epoch': False,
        'log_processor.by_epoch': False,
    })
    return options, f'iter_{max_iters}.pth'


def as_cli(options: Dict[str, Any]) -> List[str]:
    """``key=value`` words that mmengine's ``DictAction`` parses back to
    ``options`` (strings, ints, floats, booleans and ``None``)."""
    words = []
    for key, value in options.items():
        if not isinstance(value, (str, int, float, bool, type(None))):
            raise TypeError(f'{key}={value!r}: only str, int, float, bool '
                            f'and None can be passed as --cfg-options')
        if isinstance(value, str) and (not value or value.lower() in (
                'true', 'false', 'none')):
            raise ValueError(f'{key}={value!r} would not survive the '
                             f'command line as a string')
        words.append(f'{key}={value}')
    return words


def describe(enhancer: Optional[dict],
             variant_options: Optional[Dict[str, Any]] = None) -> str:
    """``TFP(window=21)``; ``none`` for raw spikes; a variant's options
    follow, e.g. ``WGSE(dim=1); ...custom_keys.enhancer.lr_mult=10``."""
    if enhancer is None:
        text = 'none'
    else:
        args = ', '.join(f'{k}={v}' for k, v in enhancer.items()
                         if k != 'type')
        text = f"{enhancer['type']}({args})"
    return '; '.join([text] + [f'{k}={v}' for k, v in
                               (variant_options or {}).items()])


def _run_logged(command: List[str], log_path: str, what: str) -> None:
    os.makedirs(osp.dirname(log_path), exist_ok=True)
    with open(log_path, 'a') as log:
        log.write(f'$ {shlex.join(command)}\n')
        log.flush()
        code = subprocess.call(command, stdout=log, stderr=subprocess.STDOUT)
    if code != 0:
        with open(log_path) as log:
            tail = ''.join(log.readlines()[-20:])
        raise RunFailed(f'{what} exited with {code}; the end of {log_path}:'
                        f'\n{tail}')


def _train(command: List[str], run_dir: str) -> Dict[str, Any]:
    """Train, adding this attempt's wall time to ``train_time.json``."""
    path = osp.join(run_dir, 'train_time.json')
    timing = dict(seconds=0.0, attempts=0)
    if osp.exists(path):
        with open(path) as f:
            timing = json.load(f)
    start = time.perf_counter()
    try:
        _run_logged(command, osp.join(run_dir, 'train.log'), 'training')
    finally:
        timing['seconds'] += time.perf_counter() - start
        timing['attempts'] += 1
        _write_json(path, timing)
    return timing


def _test_metrics(test_dir: str) -> Dict[str, float]:
    """mIoU, mAcc, aAcc from the newest test log of ``tools/test.py``
    (mmengine writes ``<work_dir>/<timestamp>/<timestamp>.json``)."""
    logs = sorted(p for p in glob.glob(osp.join(test_dir, '*', '*.json'))
                  if osp.basename(p) == osp.basename(osp.dirname(p)) +
                  '.json')
    if not logs:
        raise RunFailed(f'no test log under {test_dir}')
    with open(logs[-1]) as f:
        logged = json.load(f)
    missing = [m for m in METRICS if m not in logged]
    if missing:
        raise RunFailed(f'{logs[-1]} lacks {missing}')
    return {m: float(logged[m]) for m in METRICS}


def loss_curve(run_dir: str) -> List[List[float]]:
    """``[[iteration, loss], ...]``: the training loss mmengine logged
    (``<run_dir>/<timestamp>/vis_data/scalars.json``, the mean over each
    logging interval), in iteration order; a resumed run's later log wins
    where attempts overlap."""
    losses = {}
    for path in sorted(glob.glob(osp.join(run_dir, '*', 'vis_data',
                                          'scalars.json'))):
        with open(path) as f:
            for line in f:
                record = json.loads(line)
                if 'loss' in record and 'iter' in record:
                    losses[int(record['iter'])] = float(record['loss'])
    return [[step, losses[step]] for step in sorted(losses)]


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


def _write_json(path: str, data: Any) -> None:
    with atomic_output(path) as f:
        f.write(json.dumps(data, indent=2).encode())


class Run(NamedTuple):
    """One entry trained with one seed: where, and with which options."""
    entry: Entry
    seed: int
    run_dir: str
    model_options: Dict[str, Any]  # data and enhancer: training and test
    train_options: Dict[str, Any]  # model_options, schedule and seed
    checkpoint: str  # the final checkpoint


def plan(entries: List[Entry], args: argparse.Namespace,
         grid: Config) -> List[Run]:
    """The runs of ``entries`` over ``args.seeds``, seeds outer (a partial
    grid covers every entry with the first seeds)."""
    schedule, checkpoint = schedule_options(args.epochs, args.max_iters)
    runs = []
    for seed in args.seeds:
        for entry in entries:
            run_dir = osp.join(osp.abspath(args.work_dir), entry.name,
                               f'seed_{seed}')
            model_options = dict(grid.cfg_options)
            model_options['data_root'] = osp.abspath(args.data_root)
            for options in (entry.model_options, entry.variant_options,
                            enhancer_options(entry.enhancer)):
                model_options.update(options)
            train_options = dict(model_options, **schedule,
                                 **{'randomness.seed': seed})
            runs.append(Run(entry, seed, run_dir, model_options,
                            train_options, osp.join(run_dir, checkpoint)))
    return runs


def finished(run: Run) -> bool:
    """Whether ``run`` has its result; one made with other options (data,
    enhancer, schedule, seed) is an error, not a result to mix in."""
    path = osp.join(run.run_dir, 'result.json')
    if not osp.exists(path):
        return False
    with open(path) as f:
        made_with = json.load(f)['train_options']
    if made_with != run.train_options:
        changed = sorted(k for k in set(made_with) | set(run.train_options)
                         if made_with.get(k) != run.train_options.get(k))
        raise SystemExit(f'{path} was made with other settings '
                         f'({", ".join(changed)} differ); use another '
                         f'--work-dir')
    return True


def run_one(run: Run, keep_checkpoints: bool,
            latency: Dict[str, int]) -> Dict[str, Any]:
    """Train, test and time one run; returns (and writes) its result."""
    entry, python = run.entry, [sys.executable]
    train_command = python + [
        osp.join(PROJECT_ROOT, 'tools', 'train.py'), entry.config, '--work-dir',
        run.run_dir, '--resume', '--cfg-options', *as_cli(run.train_options)
    ]
    timing = _train(train_command, run.run_dir)
    test_dir = osp.join(run.run_dir, 'test')
    test_command = python + [
        osp.join(PROJECT_ROOT, 'tools', 'test.py'), entry.config, run.checkpoint,
        '--work-dir', test_dir, '--cfg-options', *as_cli(run.model_options)
    ]
    _run_logged(test_command, osp.join(run.run_dir, 'test.log'), 'testing')
    metrics = _test_metrics(test_dir)
    try:
        cost = validation_cost(entry.config, run.model_options,
                               run.checkpoint, **latency)
    except Exception as error:  # the run fails, the grid goes on
        raise RunFailed(f'timing the trained model failed: '
                        f'{type(error).__name__}: {error}') from error
    result = dict(
        name=entry.name, model=entry.model, enhancer_name=entry.enhancer_name,
        enhancer=entry.enhancer, seed=run.seed, **metrics,
        params=cost['params'], enhancer_params=cost['enhancer_params'],
        ms_per_image=cost['latency_ms'], image_size=cost['image_size'],
        train_seconds=timing['seconds'], train_attempts=timing['attempts'],
        loss_curve=loss_curve(run.run_dir),
        train_options=run.train_options,
        commands=[shlex.join(train_command), shlex.join(test_command)],
        environment=cost['environment'])
    _write_json(osp.join(run.run_dir, 'result.json'), result)
    if not keep_checkpoints:
        for path in glob.glob(osp.join(run.run_dir, '*.pth')) + [
                osp.join(run.run_dir, 'last_checkpoint')]:
            if osp.exists(path):
                os.remove(path)
    return result


def _mean_std(values: List[float]) -> Tuple[float, Optional[float]]:
    return (statistics.fmean(values),
            statistics.stdev(values) if len(values) > 1 else None)


def aggregate(entries: List[Entry], seeds: List[int],
              work_dir: str) -> List[Dict[str, Any]]:
    """One row per entry with finished runs: mean and standard deviation
    over seeds (``None`` with one seed) of the metrics, ms per image (each
    run's median), training time, the final training loss (the mean logged
    loss over the last quarter of the iterations) and :func:`loss_change`;
    each run's loss curve (``loss_curves``); and the entry's benchmark
    (:func:`benchmark_entry`; ``None`` where not measured)."""
    rows = []
    for entry in entries:
        results = []
        for seed in seeds:
            path = osp.join(work_dir, entry.name, f'seed_{seed}',
                            'result.json')
            if osp.exists(path):
                with open(path) as f:
                    results.append(json.load(f))
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
        row['benchmark'] = _read_benchmark(work_dir, entry)
        row['environment'] = results[0]['environment']
        row['image_size'] = results[0]['image_size']
        rows.append(row)
    return rows


def _final_loss(curve: List[List[float]]) -> Optional[float]:
    """The mean logged loss over the last quarter; ``None`` without a
    curve."""
    fourth = _quarter(curve, 4)
    return statistics.fmean(fourth) if fourth else None


def _benchmark_path(work_dir: str, entry: Entry) -> str:
    return osp.join(work_dir, entry.name, 'benchmark.json')


def _read_benchmark(work_dir: str, entry: Entry) -> Optional[Dict[str, Any]]:
    path = _benchmark_path(work_dir, entry)
    if not osp.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


def benchmark_entry(entry: Entry, model_options: Dict[str, Any],
                    work_dir: str, repeat: int,
                    warmup: int) -> Dict[str, Any]:
    """Measure the entry once with the package's benchmark
    (:func:`~wgse_mmseg.apis.benchmarking.benchmark_config`: FLOPs,
    training-step time and peak memory at the grid's crop and batch size,
    in a fresh process) unless ``WORK_DIR/<entry>/benchmark.json`` exists;
    returns (and writes) it. The result belongs to the entry, not to a
    seed; run it while nothing else loads the machine."""
    path = _benchmark_path(work_dir, entry)
    measured = _read_benchmark(work_dir, entry)
    if measured is not None:
        return measured
    options = {k: v for k, v in model_options.items() if k != 'data_root'}
    try:
        measured = run_isolated(benchmark_config, entry.config,
                                cfg_options=options, repeat=repeat,
                                warmup=warmup)
    except Exception as error:  # the report goes on without it
        raise RunFailed(f'benchmarking {entry.name} failed: '
                        f'{type(error).__name__}: {error}') from error
    measured['cfg_options'] = options
    _write_json(path, measured)
    return measured


CSV_COLUMNS = ['name', 'model', 'enhancer', 'seeds', 'mIoU_mean',
               'mIoU_std', 'mAcc_mean', 'mAcc_std', 'aAcc_mean', 'aAcc_std',
               'params', 'enhancer_params', 'ms_per_image_mean',
               'ms_per_image_std', 'train_seconds_mean', 'train_seconds_std',
               'final_loss_mean', 'final_loss_std', 'loss_change_mean',
               'loss_change_std', 'gflops', 'enhancer_gflops',
               'train_step_ms', 'train_memory_mb']


def _benchmark_columns(row: Dict[str, Any]) -> Dict[str, Any]:
    """GFLOPs (batch 1), training-step ms and peak training memory (MB)
    of the entry's benchmark; ``None`` each where not measured."""
    measured = row.get('benchmark')
    if measured is None:
        return dict(gflops=None, enhancer_gflops=None, train_step_ms=None,
                    train_memory_mb=None)

    def giga(flops):
        return None if flops is None else flops / 1e9

    return dict(gflops=giga(measured['flops']),
                enhancer_gflops=giga(measured['enhancer_flops']),
                train_step_ms=measured['train_step_ms']['median'],
                train_memory_mb=measured['memory']['peak_mb'])


def write_csv(rows: List[Dict[str, Any]], path: str) -> None:
    text = io.StringIO()
    writer = csv.DictWriter(text, CSV_COLUMNS, extrasaction='ignore',
                            lineterminator='\n')
    writer.writeheader()
    for row in rows:
        row = dict(row, **_benchmark_columns(row))
        writer.writerow({k: round(v, 4) if isinstance(v, float) else v
                         for k, v in row.items()})
    with atomic_output(path) as f:
        f.write(text.getvalue().encode())


def _pm(row: Dict[str, Any], key: str, scale: float = 1,
        digits: int = 2) -> str:
    if row[f'{key}_mean'] is None:
        return '-'
    mean, std = row[f'{key}_mean'] * scale, row[f'{key}_std']
    spread = '' if std is None else f' ± {std * scale:.{digits}f}'
    return f'{mean:.{digits}f}{spread}'


LOSS_PLOT = 'loss_curves.png'


def _total_hours(rows: List[Dict[str, Any]]) -> float:
    return sum(r['train_seconds_mean'] * r['seeds'] for r in rows) / 3600


def write_markdown(rows: List[Dict[str, Any]], path: str, command: str,
                   args: argparse.Namespace, grid: Config,
                   plot_name: str) -> None:
    """The results table, with the command, settings and machine."""
    def number(value, digits):
        return '-' if value is None else f'{value:.{digits}f}'

    table_rows = []
    for r in rows:
        cost = _benchmark_columns(r)
        table_rows.append([
            r['name'], r['enhancer'], r['seeds'], _pm(r, 'mIoU'),
            _pm(r, 'mAcc'), _pm(r, 'aAcc'), f"{r['params'] / 1e6:.3f}",
            _pm(r, 'ms_per_image', digits=1),
            _pm(r, 'train_seconds', 1 / 60, 1), _pm(r, 'final_loss'),
            _pm(r, 'loss_change', 100, 1), number(cost['gflops'], 2),
            number(cost['train_step_ms'], 0),
            number(cost['train_memory_mb'], 0)])
    table = markdown_table(
        ['entry', 'enhancer', 'seeds', 'mIoU', 'mAcc', 'aAcc', 'params (M)',
         'ms / image', 'train time (min)', 'final loss',
         'loss change, last quarter (%)', 'GFLOPs', 'train step (ms)',
         'train memory (MB)'], table_rows)
    env = rows[0]['environment']
    schedule = (f'{args.epochs} epochs' if args.max_iters is None else
                f'{args.max_iters} iterations')
    settings = ', '.join(f'{k}={v}' for k, v in grid.cfg_options.items())
    grid_name = osp.relpath(osp.abspath(args.grid))
    lines = [
        '# Accuracy against time per image', '',
        f'Grid `{grid_name}` ({settings}, '
        f'{schedule}, seeds {" ".join(map(str, args.seeds))}) on '
        f'`{args.data_root}`, made with:', '', '```bash', command, '```', '',
        f"Machine: {env['cpu']} ({env['cpu_count']} logical cores, "
        f"{env['torch_threads']} torch threads); torch {env['torch']}, "
        f"mmcv {env['mmcv']}, mmengine {env['mmengine']}, "
        f"mmsegmentation {env['mmsegmentation']}, python {env['python']}; "
        f"{env['platform']}.", '', table, '',
        '- mIoU, mAcc, aAcc: % on the validation set (MMSeg `IoUMetric`) of '
        'the final checkpoint; mean ± standard deviation over seeds (no '
        'spread with one seed).',
        '- params: used at inference, enhancer included, auxiliary head '
        'excluded.',
        '- ms / image: median of batch-1 inference (preprocessing, enhancer, '
        'segmentor, resize) on a validation-sized stream '
        f"({'x'.join(map(str, rows[0]['image_size']))}), per run; mean ± "
        'standard deviation over seeds.',
        '- train time: wall time of the training process, start-up '
        'included; mean ± standard deviation over seeds. All runs of the '
        f'table trained for {_total_hours(rows):.1f} hours in all (their '
        'training processes\' wall time, summed).',
        '- final loss: the mean logged training loss over the last quarter '
        'of the iterations; loss change: that mean against the quarter '
        'before (-5.0: still 5 % lower), the measure of how flat the curve '
        'had become; mean ± standard deviation over seeds.',
        '- GFLOPs (one stream, batch 1), train step (ms) and train memory '
        '(peak, MB): the package\'s benchmark '
        '(`wgse_mmseg.apis.benchmarking.benchmark_config`, as '
        '`tools/analysis_tools/benchmark.py`) of each entry at the training '
        'crop and batch size, measured once per entry (`--benchmark`) '
        'with nothing else running; `-`: not measured.', '',
        f'![mIoU against ms per image]({plot_name})', '',
        f'![Training loss curves]({LOSS_PLOT})'
    ]
    with atomic_output(path) as f:
        f.write(('\n'.join(lines) + '\n').encode())


def plot(rows: List[Dict[str, Any]], path: str) -> None:
    """mIoU against ms per image (log scale), error bars one standard
    deviation over seeds; marker: model, colour: enhancer type, label:
    enhancer name."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    models = sorted({r['model'] for r in rows})
    markers = dict(zip(models, 'osD^v<>p*h'))
    types = sorted({r['enhancer'].split('(')[0] for r in rows})
    colours = {t: plt.get_cmap('tab10')(i % 10) for i, t in enumerate(types)}
    figure, axes = plt.subplots(figsize=(9, 6))
    for row in rows:
        axes.errorbar(row['ms_per_image_mean'], row['mIoU_mean'],
                      xerr=row['ms_per_image_std'], yerr=row['mIoU_std'],
                      marker=markers[row['model']], linestyle='none',
                      color=colours[row['enhancer'].split('(')[0]],
                      capsize=2)
        axes.annotate(row['name'][len(row['model']) + 1:],
                      (row['ms_per_image_mean'], row['mIoU_mean']),
                      fontsize=6, xytext=(3, 3), textcoords='offset points')
    handles = [Line2D([], [], marker=markers[m], color='grey',
                      linestyle='none', label=m) for m in models]
    handles += [Line2D([], [], marker='o', color=colours[t],
                       linestyle='none', label=f'enhancer: {t}')
                for t in types]
    axes.legend(handles=handles, fontsize=7, loc='best')
    axes.set_xscale('log')
    axes.set_xlabel('ms per image (batch 1, log scale)')
    axes.set_ylabel('mIoU (%)')
    axes.set_title('Accuracy against time per image')
    axes.grid(True, which='both', alpha=0.3)
    figure.tight_layout()
    with atomic_output(path) as f:
        figure.savefig(f, format='png', dpi=150)
    plt.close(figure)


def plot_loss_curves(rows: List[Dict[str, Any]], path: str) -> None:
    """The training loss against iterations, one panel per model, one line
    per entry (the mean over its seeds at the iterations all of them
    logged; ten colours, then the next line style), the seeds' range
    shaded."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    models = list(dict.fromkeys(r['model'] for r in rows))
    figure, axes = plt.subplots(1, len(models), squeeze=False,
                                figsize=(6.5 * len(models), 5))
    for axis, model in zip(axes[0], models):
        model_rows = [r for r in rows if r['model'] == model]
        colours = plt.get_cmap('tab10')
        for index, row in enumerate(model_rows):
            curves = [dict(c) for c in row['loss_curves'] if c]
            if not curves:
                continue
            steps = sorted(set.intersection(*(set(c) for c in curves)))
            losses = np.array([[c[s] for s in steps] for c in curves])
            colour = colours(index % 10)
            axis.plot(steps, losses.mean(0), color=colour, linewidth=1.2,
                      linestyle=('-', '--', ':')[index // 10 % 3],
                      label=row['name'][len(model) + 1:])
            axis.fill_between(steps, losses.min(0), losses.max(0),
                              color=colour, alpha=0.15, linewidth=0)
        axis.set_title(f'{model}: training loss (mean over seeds)')
        axis.set_xlabel('iteration')
        axis.set_ylabel('loss')
        axis.grid(True, alpha=0.3)
        axis.legend(fontsize=7, ncol=2)
    figure.tight_layout()
    with atomic_output(path) as f:
        figure.savefig(f, format='png', dpi=120)
    plt.close(figure)


def report(entries: List[Entry], args: argparse.Namespace, grid: Config,
           command: str) -> List[Dict[str, Any]]:
    """Aggregate the finished runs and write the CSV, Markdown and plot."""
    rows = aggregate(entries, args.seeds, args.work_dir)
    if not rows:
        print('no finished runs to report')
        return rows
    report_dir = args.report_dir or args.work_dir
    plot_path = osp.join(report_dir, 'accuracy_vs_time.png')
    plot(rows, plot_path)
    plot_loss_curves(rows, osp.join(report_dir, LOSS_PLOT))
    write_csv(rows, osp.join(report_dir, 'results.csv'))
    write_markdown(rows, osp.join(report_dir, 'results.md'), command, args,
                   grid, osp.basename(plot_path))
    print(f'{len(rows)} entries reported in {report_dir}: results.md, '
          f'results.csv, accuracy_vs_time.png, {LOSS_PLOT}')
    return rows
