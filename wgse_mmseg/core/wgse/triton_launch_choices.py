"""Which launch of WGSE's Triton band kernels a call runs: the launch
entries (tile of pixels, warps, register cap) of each kernel, the precision
of the tensor-core products, the forward's product forms per GPU and the
backward's division of work among its programs.

Each kernel has a list of ``(block, num_warps)`` entries, one a list today;
a call runs the first unless its caller names another. Every entry is
compiled ahead of time for sm_80, sm_89, sm_90, sm_100 and sm_120 by
:mod:`~wgse_bench.triton_resources` and tested in the interpreter. The
launches themselves are :mod:`~wgse_mmseg.core.wgse.triton_band_networks`'.
"""
from typing import List, NamedTuple, Optional, Sequence, Tuple

import torch

from ..kernel_choices import TOLERANCES

__all__ = []


class LaunchConfig(NamedTuple):
    """How a kernel is launched: ``block`` pixels per program (``tl.dot``
    needs at least 16), ``num_warps`` warps per program and, where not
    ``None``, ``maxnreg``: the most registers a thread may use (ptxas
    spills the rest; without it ptxas chooses, and may spill to fit more
    programs an SM)."""
    block: int
    num_warps: int
    maxnreg: Optional[int] = None

    @property
    def name(self) -> str:
        """``'64x4'`` (block x warps), ``'64x4r168'`` with ``maxnreg``."""
        return f'{self.block}x{self.num_warps}' + (
            '' if self.maxnreg is None else f'r{self.maxnreg}')


#: The forward kernel's one launch entry: 128-pixel tiles, 4 warps (one
#: warp group: warp-group tensor-core instructions on sm_90), 127-255
#: registers without spilling on sm_80, sm_89, sm_90, sm_100 and sm_120 at
#: TF32, fp16 and bf16, two programs an SM (at 32 channels; 16 take
#: fewer). 256 pixels spill, and 64 cost more instructions a coefficient
#: position than 128 (the resources tool's table, docs/wgse_speed.md).
FORWARD_CONFIGS = (LaunchConfig(128, 4), )
#: The backward kernel's entries (:func:`backward_configs`), the first of a
#: list running unless a caller names another. Each compiles without
#: spilling to at least two programs an SM at every precision on sm_80,
#: sm_89, sm_90, sm_100 and sm_120 (the resources tool's table,
#: docs/wgse_speed.md, "Compiled for GPUs"): 32 pixels (48 KB of shared
#: memory at TF32: two programs share sm_89's and sm_120's 100 KB), 16
#: wherever the input gradient is computed (WGSE's coefficients need none
#: in training: they come from the data; it carries three more vectors, and
#: 32 pixels spill) or the products are full float32, with 255 registers
#: allowed: left to choose, ptxas gives its 32-channel fp16 and bf16
#: variants 168 and spills 8-16 bytes a thread to fit three programs an
#: SM. 64 pixels spill even on sm_90 at TF32.
BACKWARD_CONFIGS = dict(default=(LaunchConfig(32, 4), ),
                        input_grad=(LaunchConfig(16, 4, 255), ))
#: Programs of the backward kernel per SM the work is divided for: what
#: every entry above fits at once.
PROGRAMS_PER_SM = 2


def conv1_on_tensor_cores(precision: str, major: int) -> bool:
    """Whether the forward kernel computes conv1 as a tensor-core product
    (its window of three coefficients times the taps), for products of
    ``precision`` on a GPU of compute capability ``major`` (0: the
    interpreter): with fp16 or bf16 operands on every target, and at TF32
    where the products are tcgen05 ones (10: B200). Otherwise float32
    multiply-adds: by the resources tool's counts (docs/wgse_speed.md,
    "Compiled for GPUs") the product takes fewer instructions in fp16 and
    bf16 on every target, and at TF32 only on sm_100, where the
    multiply-adds spill; elsewhere at TF32 it costs more and spills on
    sm_89. Under fp16 and bf16 the forward's conv1 then
    rounds its operands as the backward's (and as cuDNN's under autocast)
    does."""
    return precision in ('fp16', 'bf16') or (precision == 'tf32' and
                                             major == 10)


def taps_as_one_product(precision: str, major: int) -> bool:
    """Whether the forward kernel runs conv2's taps 0 and 1 as one product
    (``TAPS_01_AS_ONE``) with products of ``precision`` on a GPU of compute
    capability ``major`` (0: the interpreter): on sm_90's tensor cores,
    whose ``wgmma`` products ptxas otherwise serialises, and in the
    interpreter at those precisions, so that its tests reach it. Full
    float32 (``'ieee'``, the FMA units) spills with it."""
    return precision != 'ieee' and major in (0, 9)


def backward_configs(input_grad: Optional[bool] = None,
                     precision: Optional[str] = None
                     ) -> Tuple[LaunchConfig, ...]:
    """The backward entries (:data:`BACKWARD_CONFIGS`) a call launches,
    computing the input gradient or not, with products of ``precision``
    (:func:`dot_precision`, needed with ``input_grad``); ``None``: every
    entry. Full float32 (``'ieee'``: TF32 turned off) runs the input
    gradient's entries either way: its products multiply on the FMA units,
    whose operands take more registers, and at 32 pixels its backward
    spills 8-40 bytes a thread on sm_80, sm_89 and sm_90 and 136-176 on
    sm_100 and sm_120 (at 16 pixels, 255 registers, nothing)."""
    if input_grad is None:
        return BACKWARD_CONFIGS['default'] + BACKWARD_CONFIGS['input_grad']
    if precision not in TOLERANCES:
        raise ValueError(f'backward_configs: precision must be one of '
                         f'{list(TOLERANCES)}, got {precision!r}')
    return BACKWARD_CONFIGS['input_grad' if input_grad or
                            precision == 'ieee' else 'default']


def dot_precision(device_type: str) -> str:
    """The precision of the ``H x H`` products for a call made now:
    ``'fp16'`` or ``'bf16'`` under autocast, else ``'tf32'`` where
    ``torch.backends.cudnn.allow_tf32``, else ``'ieee'``."""
    if torch.is_autocast_enabled(device_type):
        dtype = torch.get_autocast_dtype(device_type)
        return {torch.float16: 'fp16', torch.bfloat16: 'bf16'}.get(
            dtype, 'ieee')
    return 'tf32' if torch.backends.cudnn.allow_tf32 else 'ieee'


def work_division(lengths: Sequence[int], tiles: int, slots: int
                  ) -> List[Tuple[int, int, int]]:
    """The backward kernel's programs, ``(band, first tile, step)`` each:
    about ``slots`` programs shared among the bands in proportion to their
    work (a tile of a band of ``L`` coefficients takes ``L + 3`` steps), so
    that programs of every band finish together; at least one a band, and
    at most half its tiles, so that every program runs two tiles or more
    (where the band has two). Training sizes give each program hundreds of
    tiles; the cap binds on small problems, where it makes the first-use
    check run the kernel's sums over several tiles as training does
    (given every SM's programs, the check's would run one tile each)."""
    work = [length + 3 for length in lengths]
    counts = [min(max(1, tiles // 2), max(1, round(slots * w / sum(work))))
              for w in work]
    return [(band, first, count) for band, count in enumerate(counts)
            for first in range(count)]
