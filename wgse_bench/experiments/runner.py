"""Runs of an experiment grid: plan, train, test, time, resume.

Each (entry, seed) run trains with ``tools/train.py`` and evaluates its
final checkpoint with ``tools/test.py``, each in its own process with the
grid's ``--cfg-options``, then times batch-1 inference on a
validation-sized stream. A run is done when
``WORK_DIR/<entry>/seed_<seed>/result.json`` exists (written atomically):
re-running skips finished runs and resumes an interrupted one from its last
checkpoint. The training loss is read back from mmengine's logs
(:func:`loss_curve`); :func:`benchmark_entry` measures an entry once.
"""
import glob
import json
import os
import os.path as osp
import shlex
import subprocess
import sys
import time
from typing import Any, Dict, List, NamedTuple, Optional

from mmengine.config import Config

from wgse_mmseg.fileio.atomic import atomic_output
from wgse_mmseg.fileio.bounded_reads import load_json_file, parse_json
from wgse_mmseg.limits import LOG_FILE_LIMIT_BYTES
from wgse_mmseg.fileio.output_folder import OwnedFolder, discard, open_append

from ..machine import run_isolated
from ..segmentation import benchmark_config, validation_cost
from .grid import (PROJECT_ROOT, Entry, as_cli, enhancer_options,
                   schedule_options)
from .settings import ExperimentSettings

#: the test metrics of a run, as MMSeg's IoUMetric logs them
METRICS = ('mIoU', 'mAcc', 'aAcc')
#: the file whose presence marks a run done
RESULT = 'result.json'


class RunFailed(RuntimeError):
    """A training or test process of one run exited with an error."""


class StaleRunError(ValueError):
    """A run's result was made with other options (data, enhancer, schedule,
    seed) than the run now planned in its directory."""


def run_directory(work_dir: str, entry: Entry, seed: int) -> str:
    """Where the run of ``entry`` with ``seed`` keeps its files."""
    return osp.join(work_dir, entry.name, f'seed_{seed}')


def _run_logged(command: List[str], log_path: str, what: str) -> None:
    os.makedirs(osp.dirname(log_path), exist_ok=True)
    with open_append(log_path) as log:  # never through a link
        log.write(f'$ {shlex.join(command)}\n'.encode())
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
        timing = load_json_file(path, 'training time record')
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
    logged = load_json_file(logs[-1], 'test log', LOG_FILE_LIMIT_BYTES)
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
                record = parse_json(line, path, 'log line')
                if 'loss' in record and 'iter' in record:
                    losses[int(record['iter'])] = float(record['loss'])
    return [[step, losses[step]] for step in sorted(losses)]


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


def plan(entries: List[Entry], settings: ExperimentSettings,
         grid: Config) -> List[Run]:
    """The runs of ``entries`` over ``settings.seeds``, seeds outer (a
    partial grid covers every entry with the first seeds)."""
    schedule, checkpoint = schedule_options(settings.epochs,
                                            settings.max_iters)
    runs = []
    for seed in settings.seeds:
        for entry in entries:
            run_dir = run_directory(osp.abspath(settings.work_dir), entry,
                                    seed)
            model_options = dict(grid.cfg_options)
            model_options['data_root'] = osp.abspath(settings.data_root)
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
    enhancer, schedule, seed) is a :class:`StaleRunError`, not a result to
    mix in."""
    path = osp.join(run.run_dir, RESULT)
    if not osp.exists(path):
        return False
    made_with = load_json_file(path, 'run result',
                               LOG_FILE_LIMIT_BYTES)['train_options']
    if made_with != run.train_options:
        changed = sorted(k for k in set(made_with) | set(run.train_options)
                         if made_with.get(k) != run.train_options.get(k))
        raise StaleRunError(f'{path} was made with other settings '
                            f'({", ".join(changed)} differ); use another '
                            f'--work-dir')
    return True


def run_one(run: Run, keep_checkpoints: bool,
            latency: Dict[str, int]) -> Dict[str, Any]:
    """Train, test and time one run; returns (and writes) its result."""
    entry, python = run.entry, [sys.executable]
    train_command = python + [
        osp.join(PROJECT_ROOT, 'tools', 'train.py'), entry.config,
        '--work-dir', run.run_dir, '--resume', '--cfg-options',
        *as_cli(run.train_options)
    ]
    timing = _train(train_command, run.run_dir)
    test_dir = osp.join(run.run_dir, 'test')
    test_command = python + [
        osp.join(PROJECT_ROOT, 'tools', 'test.py'), entry.config,
        run.checkpoint, '--work-dir', test_dir, '--cfg-options',
        *as_cli(run.model_options)
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
    _write_json(osp.join(run.run_dir, RESULT), result)
    if not keep_checkpoints:
        _remove_checkpoints(run.run_dir)
    return result


def _remove_checkpoints(run_dir: str) -> None:
    """Remove the checkpoints the run's training wrote in ``run_dir`` (as
    the folder's manifest lists them: a ``.pth`` of the user's stays),
    and ``last_checkpoint`` when it names one of them."""
    owned = OwnedFolder(run_dir, claimed=True)
    removed = owned.discard_written(
        glob.glob(osp.join(glob.escape(run_dir), '*.pth')))
    last = osp.join(run_dir, 'last_checkpoint')
    if removed and osp.isfile(last) and not osp.islink(last):
        with open(last, encoding='utf-8', errors='replace') as f:
            named = f.read(4096).strip()
        if osp.abspath(named) in map(osp.abspath, removed):
            discard(last)


def _benchmark_path(work_dir: str, entry: Entry) -> str:
    return osp.join(work_dir, entry.name, 'benchmark.json')


def read_benchmark(work_dir: str, entry: Entry) -> Optional[Dict[str, Any]]:
    """The entry's measurement by :func:`benchmark_entry`; ``None`` where
    not measured."""
    path = _benchmark_path(work_dir, entry)
    if not osp.exists(path):
        return None
    return load_json_file(path, 'benchmark result')


def benchmark_entry(entry: Entry, model_options: Dict[str, Any],
                    work_dir: str, repeat: int,
                    warmup: int) -> Dict[str, Any]:
    """Measure the entry once with the package's benchmark
    (:func:`~wgse_bench.segmentation.benchmark_config`: FLOPs,
    training-step time and peak memory at the grid's crop and batch size,
    in a fresh process) unless ``WORK_DIR/<entry>/benchmark.json`` exists;
    returns (and writes) it. The result belongs to the entry, not to a
    seed; run it while nothing else loads the machine."""
    path = _benchmark_path(work_dir, entry)
    measured = read_benchmark(work_dir, entry)
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
