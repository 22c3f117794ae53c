"""What the device can do at most, measured in the run whose figures are
divided by it: its clocks, a large device-to-device copy, a large bf16
matrix product, and the tensor-core products of the band kernels' own
shapes in a loop (Triton microbenchmarks: on Hopper the forward's
128-pixel tiles run ``wgmma``, the backward's 32-pixel tiles
``mma.sync``)."""
import shutil
import statistics
import subprocess
from typing import Any, Dict, List, Optional, Sequence

import torch

from wgse_mmseg.core.wgse import triton_launch_choices

from ..timing import time_calls
from .measure import error_message

try:
    import triton
    import triton.language as tl
except ImportError:  # a CPU-only torch: the section says so
    triton = tl = None

__all__ = []

#: what ``nvidia-smi`` is asked of the clocks: report key -> query field
_CLOCKS = dict(sm_mhz='clocks.sm', sm_max_mhz='clocks.max.sm',
               memory_mhz='clocks.mem', memory_max_mhz='clocks.max.mem',
               power_w='power.draw', temperature_c='temperature.gpu')


def clocks() -> Dict[str, Any]:
    """The GPU's present and highest SM and memory clocks, power draw and
    temperature as ``nvidia-smi`` reads them now (numbers; ``None`` where
    it gives none), or ``{'note'}`` saying why there are none."""
    smi = shutil.which('nvidia-smi')
    if smi is None:
        return dict(note='no nvidia-smi on the PATH')
    proc = subprocess.run(
        [smi, '--query-gpu=' + ','.join(_CLOCKS.values()),
         '--format=csv,noheader,nounits'], capture_output=True, text=True)
    if proc.returncode != 0 or not proc.stdout.strip():
        return dict(note=f'nvidia-smi failed: {proc.stderr.strip()[-300:]}')
    values = proc.stdout.strip().splitlines()[0].split(',')

    def number(text: str) -> Optional[float]:
        try:
            return float(text)
        except ValueError:
            return None

    return {key: number(value.strip())
            for key, value in zip(_CLOCKS, values)}


def copy_bandwidth(nbytes: int, device: str, repeat: int) -> Dict[str, Any]:
    """A device-to-device copy of ``nbytes`` (random float32): ``ms``
    (median of ``repeat``) and ``tb_per_s``, counting the bytes read and
    the bytes written."""
    src = torch.rand(nbytes // 4, device=device)
    dst = torch.empty_like(src)
    wall = time_calls(lambda: dst.copy_(src), device, repeat, 2).wall
    median = statistics.median(wall)
    return dict(bytes=nbytes, ms=1e3 * median,
                tb_per_s=2 * src.numel() * 4 / median / 1e12)


def matmul_rate(size: int, device: str, repeat: int) -> Dict[str, Any]:
    """A ``size x size x size`` bf16 matrix product of random matrices
    through torch: ``ms`` (median of ``repeat``) and ``tflops``."""
    generator = torch.Generator().manual_seed(4)
    a, b = (torch.randn(size, size, generator=generator).to(
        device, torch.bfloat16) for _ in range(2))
    wall = time_calls(lambda: a @ b, device, repeat, 3).wall
    median = statistics.median(wall)
    return dict(size=size, ms=1e3 * median,
                tflops=2.0 * size ** 3 / median / 1e12)


def device_ceilings(copy_bytes: int, matmul_size: int, device: str,
                    repeat: int) -> Dict[str, Any]:
    """The ceilings section: :func:`clocks` before and after the matrix
    products (idle and under load), :func:`copy_bandwidth` and
    :func:`matmul_rate`."""
    idle = clocks() if device.startswith('cuda') else dict(
        note=f'no GPU clocks on {device}')
    copy = copy_bandwidth(copy_bytes, device, repeat)
    matmul = matmul_rate(matmul_size, device, repeat)
    loaded = clocks() if device.startswith('cuda') else idle
    return dict(clocks_idle=idle, clocks_loaded=loaded, copy=copy,
                matmul_bf16=matmul)


if triton is not None:
    @triton.jit
    def _dot_loop(a_ptr, b_ptr, out_ptr, ITERATIONS: tl.constexpr,
                  M: tl.constexpr, N: tl.constexpr, K: tl.constexpr,
                  PRECISION: tl.constexpr):
        """``ITERATIONS`` products ``(M, K) x (K, N)`` into one float32
        accumulator per program, the operands loaded once: the tensor
        cores' rate at the band kernels' tile shapes; float32 operands,
        rounded to bf16 first where ``PRECISION`` is ``'bf16'``."""
        program = tl.program_id(0)
        rows, cols, inner = (tl.arange(0, M), tl.arange(0, N),
                             tl.arange(0, K))
        a = tl.load(a_ptr + program * M * K + rows[:, None] * K +
                    inner[None, :])
        b = tl.load(b_ptr + inner[:, None] * N + cols[None, :])
        acc = tl.zeros((M, N), tl.float32)
        if PRECISION == 'bf16':
            a16, b16 = a.to(tl.bfloat16), b.to(tl.bfloat16)
            for _ in range(ITERATIONS):
                acc = tl.dot(a16, b16, acc)
        else:
            for _ in range(ITERATIONS):
                acc = tl.dot(a, b, acc, input_precision=PRECISION)
        tl.store(out_ptr + program * M * N + rows[:, None] * N +
                 cols[None, :], acc)


def _instruction(compiled: Any) -> str:
    """Which tensor-core instruction a compiled kernel's PTX holds:
    ``'wgmma'``, ``'mma.sync'`` or ``'none'``; ``'interpreted'`` without
    PTX (triton's interpreter)."""
    ptx = getattr(compiled, 'asm', {}).get('ptx') if compiled is not None \
        else None
    if not ptx:
        return 'interpreted'
    return 'wgmma' if 'wgmma.mma_async' in ptx else \
        'mma.sync' if 'mma.sync' in ptx else 'none'


def dot_rate(block: int, hidden: int, num_warps: int, precision: str,
             programs: int, iterations: int, device: str,
             repeat: int) -> Dict[str, Any]:
    """:func:`_dot_loop` of ``(block, hidden) x (hidden, hidden)``
    products at ``precision`` (``'tf32'`` or ``'bf16'`` operands) over
    ``programs`` programs of ``num_warps`` warps: ``median_ms`` of
    ``repeat``, ``tflops``, the ``instruction`` it compiled to and
    ``max_rel_error`` of its result against ``iterations`` times the
    product in float64."""
    generator = torch.Generator().manual_seed(5)
    a = torch.randn(programs, block, hidden, generator=generator).to(device)
    b = torch.randn(hidden, hidden, generator=generator).to(device)
    out = torch.full((programs, block, hidden), float('nan'), device=device)

    def launch():
        return _dot_loop[(programs, )](
            a, b, out, ITERATIONS=iterations, M=block, N=hidden, K=hidden,
            PRECISION=precision, num_warps=num_warps)

    compiled = launch()
    want = iterations * (a.double() @ b.double())
    error = ((out.double() - want).abs().max() /
             want.abs().max()).item()
    wall = time_calls(launch, device, repeat, 1).wall
    median = statistics.median(wall)
    flops = 2.0 * block * hidden * hidden * iterations * programs
    return dict(median_ms=1e3 * median, tflops=flops / median / 1e12,
                instruction=_instruction(compiled), max_rel_error=error)


def tensor_core_rates(hidden: int, programs_per_sm: int, iterations: int,
                      device: str, repeat: int) -> Dict[str, Any]:
    """:func:`dot_rate` at the tile of each band kernel's launch entry
    (the forward's, the backward's training entry at TF32), at TF32 and
    bf16: ``{'rows': [{'kernel', 'block', 'num_warps', 'precision', ...}]}``,
    ``programs_per_sm`` programs for each SM (one SM's worth on the
    CPU)."""
    if triton is None:
        return dict(rows=[], note='not run: triton does not import')
    sms = torch.cuda.get_device_properties(device).multi_processor_count \
        if device.startswith('cuda') else 1
    entries = dict(
        band_forward=triton_launch_choices.FORWARD_CONFIGS[0],
        band_backward=triton_launch_choices.backward_configs(False,
                                                             'tf32')[0])
    rows: List[Dict[str, Any]] = []
    for kernel, entry in entries.items():
        for precision in ('tf32', 'bf16'):
            row = dict(kernel=kernel, block=entry.block, hidden=hidden,
                       num_warps=entry.num_warps, precision=precision)
            try:
                row.update(dot_rate(entry.block, hidden, entry.num_warps,
                                    precision, sms * programs_per_sm,
                                    iterations, device, repeat),
                           status='ok')
            except Exception as error:  # noqa: BLE001 - one row's finding
                row.update(status='failed', error=error_message(error))
            rows.append(row)
    return dict(rows=rows)


def rates_against(rows: Sequence[Dict[str, Any]],
                  matmul_tflops: Optional[float]) -> List[Dict[str, Any]]:
    """``rows`` of :func:`tensor_core_rates`, each with ``of_matmul``: its
    rate over the large bf16 product's of the same run (``None`` where
    either is missing)."""
    return [dict(row, of_matmul=None if not matmul_tflops or
                 row.get('tflops') is None else row['tflops'] /
                 matmul_tflops) for row in rows]
