"""Train and evaluate a grid of configs over seeds; tabulate and plot.

    python tools/analysis_tools/run_experiments.py GRID --data-root DIR
        --work-dir DIR [--seeds 0 1 2] [--epochs N | --max-iters N]
        [--only NAME ...] [--report-dir DIR] [--keep-checkpoints] [--list]
        [--report-only] [--benchmark] [--deployment FILE]
        [--cfg-options KEY=VALUE ...]

GRID (e.g. configs/experiments/grid_cpu.py) lists models and enhancers; each
entry ``<model>_<enhancer>`` is the model's config with
``model.data_preprocessor.enhancer`` overridden. Each (entry, seed) run
trains with tools/train.py and evaluates its final checkpoint with
tools/test.py, each in its own process with the grid's ``--cfg-options``,
then times batch-1 inference on a validation-sized stream; ``--cfg-options``
goes to every run after the grid's own (a run made with other options is
not mixed in: it is refused, naming what differs). Each finished run prints
the time the remaining runs will take at the mean so far. A run is done
when ``WORK_DIR/<entry>/seed_<seed>/result.json`` exists (written
atomically): re-running the command skips finished runs and resumes an
interrupted one from its last checkpoint. A run another process is running
(two grid commands at once) is not run twice: it is reported failed, naming
that process (:func:`~wgse_mmseg.fileio.locks.own_folder` of its
folder). At the end, every finished run of
the selected entries and seeds is aggregated into ``results.csv``,
``results.md``, ``accuracy_vs_time.png`` and ``loss_curves.png`` in
``--report-dir`` (default: the work dir). ``--benchmark`` first measures
each reported entry once with the package's benchmark (FLOPs, training-step
time, peak memory: the table's cost columns; run it with nothing else
loading the machine); ``--deployment FILE`` adds the windows per second in
torch and ONNX Runtime that ``benchmark_deployment.py`` measured. See
docs/benchmark.md.
"""
import argparse
import os
import os.path as osp
import shlex
import sys
import time

from wgse_mmseg.command_line import EPOCHS, ITERATIONS, SEED, Path, Text
from wgse_mmseg.fileio.input_guard import OutputFolderError, keeps_inputs
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.locks import own_folder
from wgse_mmseg.utils.config import add_config_options


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('grid', type=Path(), help='grid file, e.g. '
                        'configs/experiments/grid_cpu.py')
    parser.add_argument('--data-root', type=Path(), required=True,
                        help='dataset root (Spike-Cityscapes layout)')
    parser.add_argument('--work-dir', type=Path(), required=True,
                        help='one sub-directory per entry and seed')
    parser.add_argument('--seeds', type=SEED, nargs='+',
                        help="seeds (default: the grid's)")
    schedule = parser.add_mutually_exclusive_group()
    schedule.add_argument('--epochs', type=EPOCHS,
                          help="training epochs (default: the grid's)")
    schedule.add_argument('--max-iters', type=ITERATIONS,
                          help='train for this many iterations instead')
    parser.add_argument('--only', nargs='+', metavar='NAME',
                        type=Text(empty=False),
                        help='entries to run: names or shell patterns, '
                        "e.g. 'segformer_b0_*'")
    parser.add_argument('--report-dir', type=Path(),
                        help='where results.{md,csv} and the plot go '
                        '(default: the work dir)')
    parser.add_argument('--keep-checkpoints', action='store_true',
                        help='keep each run\'s checkpoints (default: '
                        'removed once the run is done)')
    parser.add_argument('--list', action='store_true',
                        help='list the selected entries and exit')
    parser.add_argument('--report-only', action='store_true',
                        help='train nothing: report the finished runs of '
                        'the selected entries and seeds (a grid run in '
                        'stages with different seeds per entry)')
    parser.add_argument('--benchmark', action='store_true',
                        help='before reporting, measure FLOPs, training-step '
                        'time and memory of each entry with finished runs '
                        '(once per entry, in WORK_DIR/<entry>/benchmark.json)')
    parser.add_argument('--deployment', type=Path(),
                        help='JSON of tools/analysis_tools/'
                        'benchmark_deployment.py: the report gains its '
                        'windows per second (torch eager, ONNX Runtime)')
    add_config_options(parser)
    return parser


def time_left(seconds: list, remaining: int) -> str:
    """``'about N min left'`` for ``remaining`` runs at the mean of the
    finished runs' ``seconds`` (none yet: ``''``)."""
    if not seconds or not remaining:
        return ''
    left = sum(seconds) / len(seconds) * remaining
    return (f', about {left / 60:.0f} min left' if left >= 90 else
            f', about {left:.0f} s left')


def parse_args(argv=None):
    return build_parser().parse_args(argv)


def settings_from(args, grid):
    """The checked settings of the parsed command line, the grid's seeds
    and epochs filling what it leaves out."""
    from wgse_bench import experiments
    epochs = args.epochs
    if args.max_iters is None and args.epochs is None:
        epochs = grid.epochs
    return experiments.ExperimentSettings(
        grid=args.grid, data_root=args.data_root, work_dir=args.work_dir,
        seeds=args.seeds or list(grid.seeds), epochs=epochs,
        max_iters=args.max_iters, only=args.only,
        report_dir=args.report_dir, keep_checkpoints=args.keep_checkpoints,
        benchmark=args.benchmark, report_only=args.report_only,
        deployment=args.deployment)


def measure_entries(runs, grid, work_dir):
    """Benchmark each entry that has a finished run; the names that
    failed."""
    from wgse_bench import experiments
    timing = grid.get('benchmark', dict(repeat=5, warmup=2))
    failures, seen = [], set()
    for run in runs:
        if run.entry.name in seen or not experiments.finished(run):
            continue
        seen.add(run.entry.name)
        print(f'benchmark {run.entry.name} ...', flush=True)
        try:
            measured = experiments.benchmark_entry(
                run.entry, run.model_options, work_dir, **timing)
        except experiments.RunFailed as error:
            print(f'benchmark {run.entry.name}: FAILED: {error}', flush=True)
            failures.append(f'benchmark of {run.entry.name}')
            continue
        print(f"benchmark {run.entry.name}: "
              f"{measured['train_step_ms']['median']:.0f} ms per training "
              f"step, {measured['memory']['peak_mb']:.0f} MB", flush=True)
    return failures


@keeps_inputs
def main(argv=None):
    args = parse_args(argv)
    check_tool_outputs(args, 'work_dir')
    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # the MMSeg layer's set-up first
    from wgse_bench import experiments
    command = shlex.join(['python', osp.relpath(__file__, os.getcwd())] +
                         list(sys.argv[1:] if argv is None else argv))
    grid, entries = experiments.load_grid(args.grid)
    grid.cfg_options.update(args.cfg_options)
    try:
        settings = settings_from(args, grid)
    except ValueError as error:  # ArgumentError included
        raise SystemExit(f'run_experiments.py: {error}') from None
    entries = experiments.select(entries, settings.only)
    if args.list:
        for entry in entries:
            variant = experiments.describe(entry.enhancer,
                                           entry.variant_options)
            print(f'{entry.name:32s} {variant}')
        return 0
    if not settings.report_only and not osp.isdir(
            osp.join(settings.data_root, 'spike', 'train')):
        raise SystemExit(
            f'{args.data_root}/spike/train does not exist. Make the embedded '
            f'dataset with: python '
            f'tools/dataset_converters/make_synthetic_dataset.py '
            f'{args.data_root} --num-steps {grid.cfg_options["num_steps"]}')
    runs = experiments.plan(entries, settings, grid)
    try:
        # every result is checked before any run starts
        done = [experiments.finished(run) for run in runs]
    except experiments.StaleRunError as error:
        raise SystemExit(str(error)) from None
    failures, seconds = [], []
    to_run = sum(not skip for skip in done)
    for index, (run, skip) in enumerate(zip(runs, done), 1):
        prefix = f'[{index}/{len(runs)}] {run.entry.name} seed {run.seed}:'
        if skip:
            print(f'{prefix} done before, skipped', flush=True)
            continue
        if settings.report_only:
            print(f'{prefix} not run (--report-only)', flush=True)
            continue
        print(f'{prefix} running ...', flush=True)
        start = time.perf_counter()
        try:
            with own_folder(run.run_dir):
                result = experiments.run_one(
                    run, settings.keep_checkpoints, grid.latency)
        except (experiments.RunFailed, OutputFolderError) as error:
            seconds.append(time.perf_counter() - start)
            print(f'{prefix} FAILED: {error}', flush=True)
            failures.append(f'{run.entry.name} seed {run.seed}')
            continue
        seconds.append(time.perf_counter() - start)
        left = time_left(seconds, to_run - len(seconds))
        print(f"{prefix} mIoU {result['mIoU']:.2f}, "
              f"{result['ms_per_image']['median']:.1f} ms/image, "
              f'{seconds[-1]:.0f} s{left}', flush=True)
    if settings.benchmark:
        failures += measure_entries(runs, grid, settings.work_dir)
    experiments.report(entries, settings, grid, command)
    if failures:
        print(f'{len(failures)} runs failed: {", ".join(failures)}')
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
