"""WGSE forward+backward time and peak memory against the reference design.

The reference is the public WGSE implementation's design, rebuilt here only:
``pytorch_wavelets.DWT1DForward(J=level, wave=wavelet, mode='zero')`` over
every pixel's time series ``(B*H*W, 1, T)``, one ``nn.Conv1d`` band network
per band on the whole batch, ``DWT1DInverse`` back (``T + 1`` samples for odd
``T``; the extra one is dropped for the comparison). It uses the same band
network weights as the package's ``WGSE``, so outputs must agree. Each
further row is ``WGSE`` with one band-network backend
(``wgse_mmseg.core.wgse.band_network_backends``): by default every backend
that can run on ``--device`` here (CPU: ``torch`` and, where the extension
is built, ``compiled``; CUDA: ``torch`` and, where triton imports,
``triton``). Every backend recomputes hidden activations in the backward
pass.

Each measurement runs in a fresh process: peak memory is the growth of the
process's peak resident set (on ``--device cuda``: of CUDA memory allocated)
during the first forward+backward after set-up (inputs and model already
built), also per pixel (``B*H*W``); time the median (and min-max) wall time
of ``--repeat`` further forward+backward passes after one warm-up.

    python tools/analysis_tools/benchmark_wgse.py  # the issue's shapes
    python tools/analysis_tools/benchmark_wgse.py --shapes 4x41x64x64 \\
        --repeat 3
    python tools/analysis_tools/benchmark_wgse.py --out results.json
    python tools/analysis_tools/benchmark_wgse.py --device cuda \\
        --shapes 4x129x256x512

Needs ``pytorch_wavelets`` (``requirements/tests.txt``).
"""
import argparse
import sys

from wgse_bench.wgse_choices import DEFAULT_SHAPES, IMPLEMENTATIONS, SHAPE
from wgse_mmseg.command_line import Choice, Integer, Path
from wgse_mmseg.limits import MAX_REPEAT
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.input_guard import keeps_inputs


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--shapes', nargs='+', type=SHAPE,
                        default=[SHAPE(s) for s in DEFAULT_SHAPES],
                        help='BxTxHxW batches (default: %s)' %
                        ' '.join(DEFAULT_SHAPES))
    parser.add_argument('--repeat', type=Integer(1, MAX_REPEAT), default=3)
    parser.add_argument('--impls', nargs='+',
                        type=Choice(list(IMPLEMENTATIONS)),
                        help=f'rows to run, of {list(IMPLEMENTATIONS)} '
                        '(default: the reference and every backend that can '
                        'run on --device here)')
    parser.add_argument('--device', type=Choice(['cpu', 'cuda']),
                        default='cpu')
    parser.add_argument('--out', type=Path(),
                        help='also write the results as JSON')
    return parser


@keeps_inputs
def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    check_tool_outputs(args, 'out')
    # torch once the arguments are read (--help answers at once)
    import torch

    from wgse_bench.wgse import available_backends, run_benchmark
    if args.device == 'cuda' and not torch.cuda.is_available():
        parser.error('--device cuda: torch sees no CUDA device here')
    backends = available_backends(args.device)
    impls = args.impls or ['reference'] + backends
    missing = [impl for impl in impls
               if impl != 'reference' and impl not in backends]
    if missing:
        parser.error(f'--impls {" ".join(missing)}: cannot run on '
                     f'{args.device} here (available: {", ".join(backends)})')
    run_benchmark(args.shapes, impls, args.repeat, args.device, args.out)
    return 0


if __name__ == '__main__':
    sys.exit(main())
