"""Benchmark spike segmentors: parameters, FLOPs, latency, throughput,
training-step time, the enhancer's share of the step and peak memory.

    python tools/analysis_tools/benchmark.py CONFIG [CONFIG ...]
        [--device cpu|cuda] [--crop H W] [--repeat N] [--warmup N]
        [--batch-size N] [--threads N] [--out FILE]
        [--cfg-options num_steps=41 ...]

Prints a Markdown table, one row per config, with the device and software
versions beneath it; ``--out`` also writes every number (and the raw timing
samples) as JSON. Each config is measured in a fresh process; one that
fails is reported and the others are still measured (exit status 1). What
each column measures: docs/benchmark.md and wgse_bench/segmentation.py.
"""
import argparse
import json
import sys

from wgse_mmseg.command_line import REPEAT, SIDE, WARMUP, Integer, Path, Text
from wgse_mmseg.limits import MAX_BATCH_SIZE, MAX_WORKERS
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.utils.config import add_config_options


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0] + ' ' +
        __doc__.splitlines()[1])
    parser.add_argument('configs', nargs='+', metavar='CONFIG', type=Path())
    parser.add_argument('--device', type=Text(empty=False), default='cpu',
                        help='cpu, cuda or cuda:N (default: cpu)')
    parser.add_argument('--crop', type=SIDE, nargs=2, metavar=('H', 'W'),
                        help="input size (default: the config's crop_size)")
    parser.add_argument('--repeat', type=REPEAT, default=10,
                        help='timed repeats of each measurement')
    parser.add_argument('--warmup', type=WARMUP, default=2,
                        help='untimed calls before each measurement')
    parser.add_argument('--batch-size', type=Integer(1, MAX_BATCH_SIZE),
                        help='batch of the throughput and training-step '
                        "measurements (default: the config's training batch)")
    parser.add_argument('--threads', type=Integer(1, MAX_WORKERS),
                        help='torch intra-op threads (default: torch\'s)')
    parser.add_argument('--out', type=Path(),
                        help='also write the results as JSON here')
    add_config_options(parser)
    return parser


@keeps_inputs
def main():
    args = build_parser().parse_args()
    check_tool_outputs(args, 'out')
    # the stack once the arguments are read (--help answers at once)
    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # the MMSeg layer, before its import
    from wgse_bench.machine import run_isolated
    from wgse_bench.segmentation import (benchmark_config,
                                         format_results)
    from wgse_mmseg.fileio.atomic import atomic_output
    results, failures = [], []
    for config in args.configs:
        print(f'benchmarking {config} ...', flush=True)
        try:
            results.append(run_isolated(
                benchmark_config, config, device=args.device, crop=args.crop,
                repeat=args.repeat, warmup=args.warmup,
                batch_size=args.batch_size, cfg_options=args.cfg_options,
                threads=args.threads))
        except Exception as error:  # report it, measure the other configs
            print(f'{config} FAILED: {type(error).__name__}: {error}',
                  flush=True)
            failures.append(config)
    if results:
        print(format_results(results))
    if results and args.out:
        report = dict(environment=results[0]['environment'],
                      settings=vars(args), results=results,
                      failed=failures)
        with atomic_output(args.out) as f:
            f.write(json.dumps(report, indent=2).encode())
        print(f'written to {args.out}')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
