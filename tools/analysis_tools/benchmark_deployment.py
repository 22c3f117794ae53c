"""Windows per second of an experiment grid's entries in torch (eager) and
in ONNX Runtime, on this CPU.

    python tools/analysis_tools/benchmark_deployment.py GRID [--only NAME ...]
        [--shape T H W] [--batch-size 1] [--repeat 5] [--warmup 1]
        [--threads N] [--out FILE]

Each selected entry of GRID (e.g. configs/experiments/grid_cpu.py; entries
as ``run_experiments.py --list`` names them) is built with the grid's
options and random weights, timed in torch, exported to ONNX and timed in
ONNX Runtime on the same random streams, in a fresh process
(``wgse_bench.deployment``). Prints a Markdown table naming the
machine; ``--out`` writes every number as JSON, which
``run_experiments.py --deployment FILE`` adds to the report's table. An
entry that fails (TFI does not export) is reported and the others are
still measured (exit status 1).
"""
import argparse
import json
import sys

from wgse_mmseg.apis.onnx_settings import SHAPE_ENTRY
from wgse_mmseg.command_line import REPEAT, WARMUP, Integer, Path, Text
from wgse_mmseg.limits import MAX_BATCH_SIZE, MAX_WORKERS
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.input_guard import keeps_inputs


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('grid', type=Path(), help='grid file, e.g. '
                        'configs/experiments/grid_cpu.py')
    parser.add_argument('--only', nargs='+', metavar='NAME',
                        type=Text(empty=False),
                        help='entries: names or shell patterns (default: '
                        'all)')
    parser.add_argument('--shape', type=SHAPE_ENTRY, nargs=3,
                        metavar=('T', 'H', 'W'),
                        default=[41, 128, 256],
                        help='the input (default: the embedded data\'s, 41 '
                        '128 256)')
    parser.add_argument('--batch-size', type=Integer(1, MAX_BATCH_SIZE),
                        default=1, help='streams per call (default: 1)')
    parser.add_argument('--repeat', type=REPEAT, default=5,
                        help='timed calls per backend')
    parser.add_argument('--warmup', type=WARMUP, default=1,
                        help='untimed calls before them')
    parser.add_argument('--threads', type=Integer(1, MAX_WORKERS),
                        help='torch and ONNX Runtime intra-op threads, the '
                        'same for both (default: each one\'s own; 1 is '
                        'steadier on a shared machine)')
    parser.add_argument('--out', type=Path(), help='write the JSON here')
    return parser


@keeps_inputs
def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    check_tool_outputs(args, 'out')
    # the stack once the arguments are read (--help answers at once)
    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # the MMSeg layer, before its import
    from wgse_bench.experiments import load_grid, select
    from wgse_bench.experiments.grid import enhancer_options
    from wgse_bench.deployment import (format_deployment,
                                       measure_deployment)
    from wgse_bench.machine import run_isolated
    from wgse_mmseg.fileio.atomic import atomic_output
    grid, entries = load_grid(args.grid)
    results, failures = [], []
    for entry in select(entries, args.only):
        options = dict(grid.cfg_options)
        for extra in (entry.model_options, entry.variant_options,
                      enhancer_options(entry.enhancer)):
            options.update(extra)
        print(f'measuring {entry.name} ...', flush=True)
        try:
            results.append(run_isolated(
                measure_deployment, entry.name, entry.config, options,
                args.shape, batch_size=args.batch_size, repeat=args.repeat,
                warmup=args.warmup, threads=args.threads))
        except Exception as error:  # report it, measure the others
            message = str(error).splitlines()[0][:300] if str(error) else ''
            print(f'{entry.name} FAILED: {type(error).__name__}: {message}',
                  flush=True)
            failures.append(entry.name)
    if results:
        print(format_deployment(results))
    if args.out:
        with atomic_output(args.out) as f:
            f.write(json.dumps(dict(settings=vars(args), results=results,
                                    failed=failures), indent=2).encode())
        print(f'written to {args.out}')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
