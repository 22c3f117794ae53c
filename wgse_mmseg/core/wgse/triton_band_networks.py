"""WGSE's 1-D band networks as a Triton kernel (CUDA).

Runs the paper's band network (``num_blocks=1``: conv ``1 -> H``, conv
``H -> H`` plus the input, conv ``H -> 1``, each followed by ReLU; kernel 3)
for every pixel, a tile of pixels per program (:data:`FORWARD_CONFIGS`,
:data:`BACKWARD_CONFIGS`: tile and warps, tuned per GPU and shape), the
weights read once per program and the ``H x H`` layer on tensor cores
(``tl.dot``). The backward pass recomputes each tile's activations while it
streams the gradient, so nothing of size ``pixels x H`` is ever kept: the
only memory beyond the input, output and their gradients is one row of
parameter-gradient sums per program. Kernels: :mod:`._triton_band_kernels`.

Precision of the ``H x H`` products (:func:`dot_precision`): under autocast
their operands are rounded to its dtype (fp16 or bf16); otherwise TF32 where
``torch.backends.cudnn.allow_tf32`` allows it (the flag torch applies to
convolutions, on by default), else full float32. Everything else, and every
accumulation, is float32. The tolerances against float32 that the tests
hold are :data:`TOLERANCES`.

Launch configurations: each kernel has a short list of ``(block,
num_warps)`` entries. On a GPU the first call of a kernel variant (device,
band length, width, precision, input gradient, pixel count rounded up to a
power of two) times every entry once and keeps the fastest
(:func:`tuned_configs` lists the choices); under the interpreter, and where
a caller names one, a given entry runs. Every entry is compiled ahead of
time for sm_80, sm_89 and sm_90 by
:mod:`~wgse_mmseg.benchmarks.triton_resources` and tested in the
interpreter.

Triton's interpreter (``TRITON_INTERPRET=1`` in the environment before
triton is first imported) runs the same kernels on CPU tensors; the tests
use it, since CI has no GPU.
"""
import functools
import os
from typing import Callable, Dict, List, NamedTuple, Optional, Sequence, Tuple

import torch
from torch import Tensor

try:
    import triton
    import triton.testing

    from . import _triton_band_kernels as kernels
    _IMPORT_ERROR = None
except ImportError as error:  # triton is not installed (CPU-only torch)
    triton = kernels = None
    _IMPORT_ERROR = str(error)

__all__ = []


class LaunchConfig(NamedTuple):
    """How a kernel is launched: ``block`` pixels per program (``tl.dot``
    needs at least 16), ``num_warps`` warps per program and, where not
    ``None``, ``maxnreg``: the most registers a thread may use (ptxas
    spills the rest), which lets more programs share an SM."""
    block: int
    num_warps: int
    maxnreg: Optional[int] = None

    @property
    def name(self) -> str:
        """``'16x4'`` (block x warps), ``'16x4r168'`` with ``maxnreg``."""
        return f'{self.block}x{self.num_warps}' + (
            '' if self.maxnreg is None else f'r{self.maxnreg}')


#: The entries a GPU chooses from, the first being what runs untuned (the
#: interpreter's). Chosen with ``tools/analysis_tools/sweep_band_kernels.py``
#: (the longest band at T=129, 72, 32 channels, 4x256x512 pixels;
#: docs/wgse_speed.md, "Launch entries"). The forward's 64-pixel tile fills
#: its 254 registers on sm_90 without spilling and runs on warp-group
#: tensor-core instructions: 2.7 ms against the 16-pixel tile's 5.2 on one
#: H200 at TF32; the 16-pixel tile (112 registers, 4 programs an SM) stays
#: for GPUs nobody here has measured. The backward keeps one entry: it
#: carries the gradient's windows and three ``H x H`` parameter-gradient
#: sums besides the forward's, 234-255 registers at 16 pixels, and every
#: other entry measured was slower on an H100 and an H200 (2 or 8 warps;
#: 32 or 64 pixels, which spill 1-3.5 KB a thread on every target; a
#: register cap for more programs an SM) by 5% to 5x.
FORWARD_CONFIGS = (LaunchConfig(16, 4), LaunchConfig(64, 4))
BACKWARD_CONFIGS = (LaunchConfig(16, 4), )
#: Hidden widths the kernels take (``tl.dot`` needs powers of two >= 16).
#: Not 64: its TF32 backward needs 116-137 KB of shared memory a program,
#: more than sm_89 (L40, RTX 4090) gives one (99 KB), and spills 0.5-1.5 KB
#: a thread on every target; the 'torch' backend runs it.
HIDDEN_CHANNELS = (16, 32)
#: Largest error against float64, relative to the largest magnitude of the
#: output or of each gradient, that the tests allow per
#: :func:`dot_precision` (measured over six seeds at 1x41x5x7: fp16 up to
#: 1.8e-2, bf16 up to 1.7e-1, on the gradients; fp32 about 1e-6). TF32
#: keeps fp16's 10 mantissa bits, bf16 7.
TOLERANCES = {'ieee': 1e-4, 'tf32': 3e-2, 'fp16': 3e-2, 'bf16': 2.5e-1}


def interpreting() -> bool:
    """Whether triton runs kernels in its CPU interpreter."""
    return os.environ.get('TRITON_INTERPRET', '0') not in ('', '0')


def unavailable() -> Optional[str]:
    """Why the Triton kernel cannot run in this installation, or ``None``."""
    if triton is None:
        return f'triton does not import ({_IMPORT_ERROR})'
    return None


def unsupported_network(dim: int, kernel_size: int, hidden_channels: int,
                        num_blocks: int) -> Optional[str]:
    """Why the kernel cannot run a band network of this shape, or ``None``."""
    if dim != 1:
        return f'it runs dim=1 band networks, not dim={dim}'
    if kernel_size != 3 or num_blocks != 1:
        return (f'it runs the paper\'s network (kernel_size=3, '
                f'num_blocks=1), not kernel_size={kernel_size}, '
                f'num_blocks={num_blocks}')
    if hidden_channels not in HIDDEN_CHANNELS:
        return (f'it runs hidden_channels in {HIDDEN_CHANNELS}, not '
                f'{hidden_channels}')
    return None


def unsupported_tensor(coeffs: Tensor) -> Optional[str]:
    """Why the kernel cannot run on ``coeffs``, or ``None``: float32 CUDA
    tensors (CPU tensors under the interpreter)."""
    device = 'cpu' if interpreting() else 'cuda'
    if coeffs.device.type != device:
        return (f'it runs on {device} tensors' +
                ('' if interpreting() else
                 ' (CPU tensors only under TRITON_INTERPRET=1)'))
    if coeffs.dtype != torch.float32:
        return f'it runs float32, not {coeffs.dtype}'
    return None


def dot_precision(device_type: str) -> str:
    """The precision of the ``H x H`` products for a call made now:
    ``'fp16'`` or ``'bf16'`` under autocast, else ``'tf32'`` where
    ``torch.backends.cudnn.allow_tf32``, else ``'ieee'``."""
    if torch.is_autocast_enabled(device_type):
        dtype = torch.get_autocast_dtype(device_type)
        return {torch.float16: 'fp16', torch.bfloat16: 'bf16'}.get(
            dtype, 'ieee')
    return 'tf32' if torch.backends.cudnn.allow_tf32 else 'ieee'


def _band_params(params: Sequence[Tensor], band: int) -> List[Tensor]:
    return [p.contiguous() for p in params[6 * band:6 * band + 6]]


class _Tuned(NamedTuple):
    """What the autotuner chose for one variant, and the time in
    milliseconds it measured for each entry it chose from."""
    config: LaunchConfig
    entry_ms: Tuple[Tuple[LaunchConfig, float], ...]


#: (device name, kernel, band length, width, precision, input gradient,
#: pixels rounded up to a power of two) -> the choice
_TUNED: Dict[tuple, _Tuned] = {}


def tuned_configs() -> Dict[str, Dict[str, object]]:
    """The entries chosen so far in this process, by a readable key
    (``'NVIDIA H100 | band_backward | L=72 H=32 tf32 input_grad=False |
    <=524288 px'``): ``{'entry', 'entry_ms'}``, the chosen entry's
    :attr:`LaunchConfig.name` and each entry's name mapped to its measured
    milliseconds."""
    return {f'{device} | {kernel} | L={length} H={hidden} {precision}'
            f'{"" if grad is None else f" input_grad={grad}"} | <={px} px':
            dict(entry=tuned.config.name, entry_ms={
                entry.name: ms for entry, ms in tuned.entry_ms})
            for (device, kernel, length, hidden, precision, grad, px),
            tuned in _TUNED.items()}


def _choose(configs: Sequence[LaunchConfig], key: tuple, device: torch.device,
            launch: Callable[[LaunchConfig], None]) -> LaunchConfig:
    """The entry of ``configs`` for this call: the first under the
    interpreter; on a GPU the fastest of one timing of each (after a
    compiling run), remembered per ``key`` and device."""
    if interpreting():
        return configs[0]
    pixels = key[-1]
    full_key = (torch.cuda.get_device_name(device), *key[:-1],
                1 << max(pixels - 1, 0).bit_length())
    if full_key not in _TUNED:
        times = [triton.testing.do_bench(lambda c=c: launch(c), warmup=1,
                                         rep=5) for c in configs]
        _TUNED[full_key] = _Tuned(configs[times.index(min(times))],
                                  tuple(zip(configs, times)))
    return _TUNED[full_key].config


def launch_forward(config: LaunchConfig, coeffs: Tensor, out: Tensor,
                   offset: int, length: int, params: Sequence[Tensor],
                   precision: str) -> None:
    """One launch of ``band_forward``: the network of the band in columns
    ``offset:offset + length`` of ``coeffs`` ``(N, C)``, into the same
    columns of ``out``; ``params`` the band's six contiguous tensors."""
    pixels, columns = coeffs.shape
    kernels.band_forward[(triton.cdiv(pixels, config.block), )](
        coeffs, out, columns, offset, pixels, *params, LENGTH=length,
        HIDDEN=params[0].shape[0], BLOCK=config.block, PRECISION=precision,
        num_warps=config.num_warps, maxnreg=config.maxnreg)


def launch_backward(config: LaunchConfig, coeffs: Tensor, grad_out: Tensor,
                    grad_coeffs: Optional[Tensor], offset: int, length: int,
                    params: Sequence[Tensor], precision: str) -> Tensor:
    """One launch of ``band_backward`` for the band of
    :func:`launch_forward`: the input gradient into those columns of
    ``grad_coeffs`` (none if ``None``). Returns the parameter-gradient sums,
    one row per program ``(programs, P)``; their sum over rows is the
    gradient of the six parameters, flattened and concatenated."""
    pixels, columns = coeffs.shape
    partial = coeffs.new_empty(triton.cdiv(pixels, config.block),
                               sum(p.numel() for p in params))
    kernels.band_backward[(partial.shape[0], )](
        coeffs, grad_out, coeffs if grad_coeffs is None else grad_coeffs,
        partial, columns, offset, pixels, *params, LENGTH=length,
        HIDDEN=params[0].shape[0], BLOCK=config.block, PRECISION=precision,
        INPUT_GRAD=grad_coeffs is not None, num_warps=config.num_warps,
        maxnreg=config.maxnreg)
    return partial


class _TritonBandNetworks(torch.autograd.Function):
    """Autograd wrapper; see :func:`triton_band_networks`."""

    @staticmethod
    def forward(ctx, coeffs: Tensor, lengths: Tuple[int, ...],
                precision: str, configs: Tuple[Optional[LaunchConfig], ...],
                *params: Tensor) -> Tensor:
        pixels = coeffs.shape[0]
        hidden = params[0].shape[0]
        out = torch.empty_like(coeffs)
        offset = 0
        for band, length in enumerate(lengths):
            launch = functools.partial(launch_forward, coeffs=coeffs, out=out,
                                       offset=offset, length=length,
                                       params=_band_params(params, band),
                                       precision=precision)
            if pixels:
                launch(configs[0] or _choose(
                    FORWARD_CONFIGS, ('band_forward', length, hidden,
                                      precision, None, pixels),
                    coeffs.device, launch))
            offset += length
        ctx.lengths, ctx.precision = lengths, precision
        ctx.backward_config = configs[1]
        ctx.save_for_backward(coeffs, *params)
        return out

    @staticmethod
    def backward(ctx, grad_out: Tensor):
        coeffs, *params = ctx.saved_tensors
        pixels = coeffs.shape[0]
        hidden = params[0].shape[0]
        input_grad = ctx.needs_input_grad[0]
        grad_out = grad_out.contiguous()
        grad_coeffs = torch.empty_like(coeffs) if input_grad else None
        grads, offset = [], 0
        for band, length in enumerate(ctx.lengths):
            band_params = _band_params(params, band)
            sizes = [p.numel() for p in band_params]
            launch = functools.partial(launch_backward, coeffs=coeffs,
                                       grad_out=grad_out,
                                       grad_coeffs=grad_coeffs, offset=offset,
                                       length=length, params=band_params,
                                       precision=ctx.precision)
            if pixels:
                total = launch(ctx.backward_config or _choose(
                    BACKWARD_CONFIGS, ('band_backward', length, hidden,
                                       ctx.precision, input_grad, pixels),
                    coeffs.device, launch)).sum(0)
            else:
                total = coeffs.new_zeros(sum(sizes))
            grads += [g.view_as(p) for g, p in
                      zip(total.split(sizes), band_params)]
            offset += length
        return (grad_coeffs, None, None, None, *grads)


def triton_band_networks(coeffs: Tensor, lengths: Sequence[int],
                         weights: Sequence[Sequence[Tuple[Tensor, Tensor]]],
                         precision: str = 'ieee',
                         forward_config: Optional[LaunchConfig] = None,
                         backward_config: Optional[LaunchConfig] = None
                         ) -> Tensor:
    """Run one band network per band over every pixel's coefficients.

    Args:
        coeffs: ``(N, C)`` float32 coefficients of ``N`` pixels, the bands
            side by side (``C = sum(lengths)``), on CUDA (on the CPU under
            the interpreter).
        lengths: ``L`` of each band.
        weights: per band, the three convolutions' ``(weight, bias)``:
            ``(H, 1, 3)``, ``(H, H, 3)``, ``(1, H, 3)`` and ``(H,)``,
            ``(H,)``, ``(1,)``, float32.
        precision: of the ``H x H`` products (:func:`dot_precision`).
        forward_config, backward_config: the launch of each kernel; by
            default the tuned choice among :data:`FORWARD_CONFIGS` and
            :data:`BACKWARD_CONFIGS` (their first entries under the
            interpreter).

    Returns:
        ``(N, C)``: each band's network output in place of its input.
        Gradients flow to ``coeffs`` and every parameter.
    """
    reason = unavailable() or unsupported_tensor(coeffs)
    if reason:
        raise ValueError(f'the Triton band network kernel cannot run here: '
                         f'{reason}')
    if precision not in TOLERANCES:
        raise ValueError(f'precision must be one of {list(TOLERANCES)}, got '
                         f'{precision!r}')
    if len(weights) != len(lengths) or sum(lengths) != coeffs.shape[1] or \
            min(lengths, default=1) < 1:
        raise ValueError(
            f'{len(weights)} band networks and bands of lengths '
            f'{list(lengths)} do not fit coefficients shaped '
            f'{tuple(coeffs.shape)}')
    hidden = weights[0][0][0].shape[0]
    reason = unsupported_network(1, 3, hidden, 1)
    if reason:
        raise ValueError(f'the Triton band network kernel: {reason}')
    expected = [(hidden, 1, 3), (hidden, ), (hidden, hidden, 3), (hidden, ),
                (1, hidden, 3), (1, )]
    params = [t for band in weights for layer in band for t in layer]
    for band in weights:
        shapes = [tuple(t.shape) for layer in band for t in layer]
        if shapes != expected:
            raise ValueError(f'the Triton kernel runs conv 1->H, H->H, H->1 '
                             f'(kernel 3) band networks: expected parameter '
                             f'shapes {expected}, got {shapes}')
    if any(p.dtype != torch.float32 or p.device != coeffs.device
           for p in params):
        raise ValueError('the Triton kernel needs float32 parameters on '
                         f'{coeffs.device}')
    for name, config, allowed in (
            ('forward_config', forward_config, FORWARD_CONFIGS),
            ('backward_config', backward_config, BACKWARD_CONFIGS)):
        if config is not None and config not in allowed:
            raise ValueError(f'{name} must be one of {list(allowed)} (the '
                             f'entries compiled and tested), got {config!r}')
    return _TritonBandNetworks.apply(coeffs.contiguous(), tuple(lengths),
                                     precision,
                                     (forward_config, backward_config),
                                     *params)
