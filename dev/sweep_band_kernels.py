r"""Time WGSE's Triton band kernels at any launch entry, one band at a time:
how the library's ``FORWARD_CONFIGS`` and ``BACKWARD_CONFIGS`` are chosen.
The backward entry times the backward kernel alone, from the gradient
at the last convolution's pre-activation that the forward kernel's mask
gives.

A maintainers' tool. For one band (``--length`` coefficients, ``--hidden``
channels, ``--precision`` of the ``H x H`` products) over ``--pixels``
pixels, each candidate entry of ``--forward`` and ``--backward`` (``BxW``:
``B`` pixels a program, ``W`` warps; ``BxWrR``: at most ``R`` registers a
thread) runs once to compile (the seconds are reported), is compared with
the first candidate of its kernel (largest difference relative to the
largest magnitude of the output, the parameter gradients and, with
``--input-grad``, the input gradient), then timed: on a GPU the median of
``triton.testing.do_bench``, in triton's CPU interpreter
(``TRITON_INTERPRET=1``, for checking the arithmetic at small sizes) the
median wall time of ``--repeat`` calls. Prints a Markdown table after the
machine it ran on; entries the library lists are marked ``*``.

    python dev/sweep_band_kernels.py    # L=72, 4x256x512 px
    python dev/sweep_band_kernels.py --precision bf16 \
        --backward 32x4 64x4
    TRITON_INTERPRET=1 python dev/sweep_band_kernels.py \
        --pixels 40 --length 9 --forward 16x4 32x4 --backward 16x4
"""
import argparse
import json
import re
import statistics
import sys
import time
from typing import Dict, List, Optional, Sequence, Tuple

from wgse_bench.markdown import markdown_table
from wgse_bench.timing import time_calls
from wgse_bench.wgse_choices import PRECISIONS
from wgse_mmseg.command_line import Choice, Integer, Path, Text, excerpt
from wgse_mmseg.core.kernel_choices import HIDDEN_CHANNELS
from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.limits import MAX_REPEAT

#: the longest band of WGSE's default (db8, 5 levels) at T = 129
BAND_LENGTH = 72
DEFAULT_FORWARD = ['128x4', '64x4', '128x8', '256x8']
DEFAULT_BACKWARD = ['32x4', '64x4', '16x4r255', '64x8', '32x2']


def launch_entry(text: str) -> Tuple[int, int, Optional[int]]:
    """``'16x4'`` or ``'16x4r168'`` as a launch entry's ``(block, warps,
    registers)`` (``LaunchConfig``'s fields); ``ValueError`` for one that
    cannot launch."""
    match = re.fullmatch(r'(\d{1,4})x(\d{1,2})(?:r(\d{1,3}))?', text)
    if match is None:
        raise ValueError(f'expected BLOCKxWARPS or BLOCKxWARPSrREGISTERS '
                         f'(16x4, 16x4r168), got {excerpt(text)}')
    block, warps, registers = (None if g is None else int(g)
                               for g in match.groups())
    if block < 16 or block & (block - 1) or warps & (warps - 1) or \
            not 1 <= warps <= 16 or \
            (registers is not None and not 24 <= registers <= 255):
        raise ValueError(f'{excerpt(text)}: the block must be a power of '
                         f'two >= 16 (tl.dot), the warps a power of two in '
                         f'[1, 16], the registers in [24, 255]')
    return block, warps, registers


def _band(length: int, hidden: int, pixels: int, device: str) -> Dict:
    """Coefficients ``(1, length, pixels)``, an output gradient of the
    same shape and one band network's six parameters, seeded."""
    import torch
    generator = torch.Generator().manual_seed(0)
    layers = [torch.nn.Conv1d(1, hidden, 3),
              torch.nn.Conv1d(hidden, hidden, 3),
              torch.nn.Conv1d(hidden, 1, 3)]
    with torch.no_grad():
        for layer in layers:  # biases that keep many ReLUs open
            layer.bias.uniform_(-0.2, 0.4, generator=generator)
    params = [t.detach().to(device).contiguous() for layer in layers
              for t in (layer.weight, layer.bias)]
    coeffs = torch.randn(1, length, pixels, generator=generator).to(device)
    grad_out = torch.randn(1, length, pixels, generator=generator).to(device)
    return dict(coeffs=coeffs, grad_out=grad_out, params=params)


def _runner(kernel: str, band: Dict, precision: str, input_grad: bool):
    """A function of a launch entry that runs ``kernel`` once and returns
    what it computed (a list of tensors)."""
    import torch

    from wgse_mmseg.core.wgse import triton_band_networks as tbn
    from wgse_mmseg.core.wgse.triton_launch_choices import FORWARD_CONFIGS
    coeffs, length = band['coeffs'], band['coeffs'].shape[1]
    inputs = tbn.band_kernel_inputs([length], band['params'])
    if kernel == 'band_backward':  # the backward kernel's input
        _, positive = tbn.launch_forward(FORWARD_CONFIGS[0], coeffs,
                                         inputs, precision)
        d3 = tbn.relu_gradient(band['grad_out'], positive)
    slots = tbn.backward_slots(coeffs.device, 1)

    def run(config):
        if kernel == 'band_forward':
            out, positive = tbn.launch_forward(config, coeffs, inputs,
                                               precision)
            return [out, positive.float()]
        grad_coeffs = torch.empty_like(coeffs) if input_grad else None
        grads = tbn.launch_backward(config, coeffs, d3, grad_coeffs, inputs,
                                    precision, slots)
        return grads + ([grad_coeffs] if input_grad else [])

    return run


def _difference(got: Sequence, want: Sequence) -> float:
    """Largest ``|got - want|`` relative to ``want``'s largest magnitude,
    over the tensors."""
    return max(((g - w).abs().max() / w.abs().max().clamp_min(1e-30)).item()
               for g, w in zip(got, want))


def _milliseconds(fn, device: str, repeat: int) -> float:
    if device == 'cuda':
        import triton.testing
        return triton.testing.do_bench(fn, return_mode='median')
    return 1e3 * statistics.median(time_calls(fn, device, repeat, 0).wall)


def sweep(kernel: str, entries: Sequence, band: Dict, precision: str,
          input_grad: bool, device: str, repeat: int) -> List[Dict]:
    """One row per entry (a ``LaunchConfig``): ``entry``, ``listed``,
    ``compile_s``, ``ms`` and ``difference`` (from the first entry's
    results)."""
    import torch

    from wgse_mmseg.core.wgse.triton_launch_choices import (FORWARD_CONFIGS,
                                                            backward_configs)
    run = _runner(kernel, band, precision, input_grad)
    listed = (FORWARD_CONFIGS if kernel == 'band_forward' else
              backward_configs())
    rows, first = [], None
    for entry in entries:
        start = time.perf_counter()
        results = run(entry)
        if device == 'cuda':
            torch.cuda.synchronize()
        compile_s = time.perf_counter() - start
        if first is None:
            first = results
        rows.append(dict(kernel=kernel, entry=entry.name,
                         listed=entry in listed, compile_s=compile_s,
                         ms=_milliseconds(lambda: run(entry), device, repeat),
                         difference=_difference(results, first)))
        print(f'[sweep] {kernel} {entry.name}: {rows[-1]["ms"]:.3f} ms',
              file=sys.stderr, flush=True)
    return rows


def format_rows(rows: Sequence[Dict]) -> str:
    """The rows as a Markdown table."""
    return markdown_table(
        ['kernel', 'entry', 'compile s', 'ms', 'difference from the first'],
        [[r['kernel'], r['entry'] + (' *' if r['listed'] else ''),
          f"{r['compile_s']:.1f}", f"{r['ms']:.3f}",
          f"{r['difference']:.1e}"] for r in rows])


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--length', type=Integer(1, 4096),
                        default=BAND_LENGTH,
                        help=f'the band\'s coefficients (default '
                        f'{BAND_LENGTH}: the longest band at T=129)')
    parser.add_argument('--hidden', type=Choice(list(HIDDEN_CHANNELS)),
                        default=32)
    parser.add_argument('--precision', type=Choice(list(PRECISIONS)),
                        default='tf32')
    parser.add_argument('--pixels', type=Integer(1, 1 << 26),
                        default=4 * 256 * 512)
    parser.add_argument('--forward', nargs='*', type=Text(empty=False),
                        default=DEFAULT_FORWARD, metavar='ENTRY',
                        help='entries of band_forward, BxW or BxWrR '
                        f'(default: {" ".join(DEFAULT_FORWARD)}; none: skip)')
    parser.add_argument('--backward', nargs='*', type=Text(empty=False),
                        default=DEFAULT_BACKWARD, metavar='ENTRY',
                        help='entries of band_backward (default: '
                        f'{" ".join(DEFAULT_BACKWARD)}; none: skip)')
    parser.add_argument('--input-grad', action='store_true',
                        help='the backward also computes the input gradient')
    parser.add_argument('--repeat', type=Integer(1, MAX_REPEAT), default=3,
                        help='timed calls in the interpreter (a GPU times '
                        'with do_bench)')
    parser.add_argument('--out', type=Path(),
                        help='also write the machine and rows as JSON')
    return parser


@keeps_inputs
def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    check_tool_outputs(args, 'out')
    entries = {}
    for option in ('forward', 'backward'):
        try:
            entries[option] = [launch_entry(e)
                               for e in getattr(args, option)]
        except ValueError as error:
            parser.error(f'argument --{option}: {error}')
    import torch

    from wgse_bench.machine import machine_record
    from wgse_mmseg.core.wgse import triton_band_networks as tbn
    from wgse_mmseg.core.wgse.triton_launch_choices import LaunchConfig
    from wgse_mmseg.fileio.atomic import atomic_output
    entries = {option: [LaunchConfig(*e) for e in listed]
               for option, listed in entries.items()}
    reason = tbn.unavailable()
    if reason:
        parser.error(f'the Triton kernels cannot run here: {reason}')
    device = 'cpu' if tbn.interpreting() else 'cuda'
    if device == 'cuda' and not torch.cuda.is_available():
        parser.error('torch sees no CUDA device: run on a GPU, or set '
                     'TRITON_INTERPRET=1 to check the arithmetic on the CPU')
    band = _band(args.length, args.hidden, args.pixels, device)
    rows = []
    for option in ('forward', 'backward'):
        rows += sweep(f'band_{option}', entries[option], band, args.precision,
                      args.input_grad, device, args.repeat)
    machine = machine_record(device)
    print(f"{machine.get('gpu', machine['cpu'])} | torch {machine['torch']} "
          f"| triton {machine['triton']} | L={args.length} H={args.hidden} "
          f"{args.precision} | {args.pixels} pixels | input gradient: "
          f"{args.input_grad}\n")
    print(format_rows(rows))
    if args.out:
        record = dict(machine=machine, arguments=dict(
            length=args.length, hidden=args.hidden,
            precision=args.precision, pixels=args.pixels,
            input_grad=args.input_grad), rows=rows)
        with atomic_output(args.out) as f:
            f.write(json.dumps(record, indent=1).encode())
    return 0


if __name__ == '__main__':
    sys.exit(main())
