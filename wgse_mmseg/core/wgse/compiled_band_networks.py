"""WGSE's 1-D band networks as one compiled CPU kernel.

``_band_networks.c`` (built by ``setup.py``) runs the paper's band network
shape, float32, kernel 3, 32 hidden channels, any number of blocks, with
AVX2/FMA register-blocked products whose bias, residual and ReLU are fused
in, over groups of pixels whose activations stay in the L2 cache; its
backward pass recomputes a group's activations in cache and accumulates the
parameter gradients in double. It computes no gradient for the
coefficients: WGSE's input is spike data.

:func:`unsupported` says why a call cannot use it; WGSE's ``'auto'``
backend (:mod:`~wgse_mmseg.core.wgse.band_network_backends`) then runs
:func:`~wgse_mmseg.core.wgse.torch_band_networks.torch_band_networks` (torch
operations, any width, kernel, dtype, device, and the input gradient).
Both compute the function of
:class:`~wgse_mmseg.core.wgse.band_network.BandNetwork`; tests compare them.

Calls are split into chunks of about :data:`ROWS_PER_CALL` rows of one
band, which run side by side on torch's threads
(:func:`~wgse_mmseg.core.parallel.for_each_on_threads`) with the GIL released;
the parameter gradients of fixed groups of chunks are summed apart and the
groups added in order, so results depend neither on timing nor on the
thread count. A backward pass with ``create_graph=True`` (second-order
gradients) runs
:func:`~wgse_mmseg.core.wgse.torch_band_networks.differentiable_backward`
instead.
"""
from itertools import accumulate
from typing import List, Optional, Sequence, Tuple

import torch
from torch import Tensor

from ..parallel import for_each_on_threads
from .torch_band_networks import (InOrder, chunk_groups,
                                  differentiable_backward, op_residuals,
                                  residual_plan)

try:
    from . import _band_networks
except ImportError:  # installed without a C compiler
    _band_networks = None

__all__ = []

#: :func:`unavailable`'s reason where the extension was not built
NOT_BUILT = ('the compiled extension was not built (installed without a C '
             'compiler)')
#: Rows (pixel coefficients plus two padding rows per pixel) per call: the
#: kernel works through them in cache-sized groups itself.
ROWS_PER_CALL = 16384
KERNEL_SIZE = 3
CHANNELS = 32


#: whether the CPU has what the extension needs (asked once, here: a call
#: into the extension is opaque to ``torch.compile``)
_CPU_SUPPORTED = _band_networks is not None and _band_networks.supported()


def unavailable() -> Optional[str]:
    """Why this installation cannot run the kernel at all, or ``None``."""
    if _band_networks is None:
        return NOT_BUILT
    if not _CPU_SUPPORTED:
        return 'this CPU lacks AVX2/FMA'
    return None


def unsupported(coeffs: Tensor,
                weights: Sequence[Sequence[Tuple[Tensor, Tensor]]],
                residuals: Sequence[Optional[int]]) -> Optional[str]:
    """Why :func:`compiled_band_networks` cannot run these band networks, or
    ``None`` where it can: it needs the extension built and a CPU with AVX2
    and FMA, float32 on the CPU, kernel 3 and 32 channels, at least two
    layers, no residual into the first or last layer, and no gradient
    wanted for ``coeffs``."""
    reason = unavailable()
    if reason:
        return reason
    if coeffs.device.type != 'cpu' or coeffs.dtype != torch.float32:
        return (f'it runs float32 CPU tensors, got {coeffs.dtype} on '
                f'{coeffs.device.type}')
    if torch.is_grad_enabled() and coeffs.requires_grad:
        return 'it computes no gradient for its input'
    if len(weights[0]) < 2 or residuals[0] is not None or \
            residuals[-1] is not None:
        return 'it runs residual layers followed by output convolutions only'
    for band in weights:
        for index, (weight, bias) in enumerate(band):
            expected = (1 if index == len(band) - 1 else CHANNELS,
                        1 if index == 0 else CHANNELS, KERNEL_SIZE)
            if tuple(weight.shape) != expected or \
                    weight.dtype != torch.float32:
                return (f'it runs kernel {KERNEL_SIZE} and {CHANNELS} '
                        f'float32 channels, got a weight shaped '
                        f'{tuple(weight.shape)} ({weight.dtype})')
    return None


def _pack(band: Sequence[Tuple[Tensor, Tensor]]) -> Tensor:
    """One band's parameters in the kernel's layout (``_band_networks.c``):
    per layer, the forward taps ``(k * C_in, C_out)``, the bias and, for
    wide layers, the flipped transposed taps ``(k * C_out, C_in)``."""
    parts = []
    for index, (weight, bias) in enumerate(band):
        parts += [weight.detach().permute(2, 1, 0).reshape(-1),
                  bias.detach().reshape(-1)]
        if 0 < index < len(band) - 1:
            parts.append(weight.detach().flip(2).permute(2, 0, 1).reshape(-1))
    return torch.cat(parts).contiguous()


def _grad_size(band: Sequence[Tuple[Tensor, Tensor]]) -> int:
    return sum(weight.numel() + bias.numel() for weight, bias in band)


def _unpack_grads(flat: Tensor, band: Sequence[Tuple[Tensor, Tensor]]
                  ) -> List[Tensor]:
    """``[dW_1, db_1, ...]`` in the parameters' shapes and dtypes from the
    kernel's ``(k * C_in, C_out)`` layout."""
    grads, start = [], 0
    for weight, bias in band:
        out_channels, in_channels, kernel_size = weight.shape
        taps = flat[start:start + weight.numel()].view(
            kernel_size, in_channels, out_channels)
        start += weight.numel()
        grads += [taps.permute(2, 1, 0).to(weight.dtype).contiguous(),
                  flat[start:start + bias.numel()].to(bias.dtype)]
        start += bias.numel()
    return grads


class _Bands:
    """Per-band arguments of the kernel, and the chunks of a call."""

    def __init__(self, coeffs: Tensor, lengths: Sequence[int],
                 weights: Sequence[Sequence[Tuple[Tensor, Tensor]]],
                 residuals: Sequence[Optional[int]]):
        self.coeffs = coeffs
        self.lengths = list(lengths)
        #: first column of each band in ``coeffs``
        self.offsets = list(accumulate(self.lengths, initial=0))[:-1]
        self.params = [_pack(band) for band in weights]
        self.residuals = torch.tensor(op_residuals(residuals),
                                      dtype=torch.int64)
        self.layers = len(residuals)
        #: each band's slice of the gradient buffer (all bands side by side)
        ends = list(accumulate(_grad_size(band) for band in weights))
        self.grad_slices = [slice(end - _grad_size(band), end)
                            for band, end in zip(weights, ends)]
        self.grad_total = ends[-1] if ends else 0
        self.chunks = []  # (band, first pixel, pixels)
        pixels = coeffs.shape[0]
        for band, length in enumerate(self.lengths):
            step = max(1, ROWS_PER_CALL // (length + 2))
            self.chunks += [(band, first, min(step, pixels - first))
                            for first in range(0, pixels, step)]

    def grad_range(self, chunks: range) -> slice:
        """The elements of the whole gradient (every band's, side by side)
        that ``chunks`` (consecutive) add to: their bands'."""
        first, last = (self.chunks[c][0] for c in (chunks[0], chunks[-1]))
        return slice(self.grad_slices[first].start,
                     self.grad_slices[last].stop)

    def run(self, chunk: int, out: Optional[Tensor] = None,
            grad_out: Optional[Tensor] = None,
            grads: Optional[Tensor] = None, grads_start: int = 0) -> None:
        """Forward into ``out``, or backward of ``grad_out`` into the
        double ``grads``: the bands' gradients side by side from element
        ``grads_start`` of the whole (:meth:`grad_range`)."""
        band, first, pixels = self.chunks[chunk]
        stride = self.coeffs.stride(0)
        element = self.coeffs.element_size()

        def address(tensor: Optional[Tensor]) -> int:
            if tensor is None:
                return 0
            return tensor.data_ptr() + element * (
                first * stride + self.offsets[band])

        grad_address = 0
        if grads is not None:
            grad_address = grads.data_ptr() + grads.element_size() * (
                self.grad_slices[band].start - grads_start)
        _band_networks.run(
            address(self.coeffs), stride, address(grad_out), stride,
            address(out), stride, pixels, self.lengths[band], self.layers,
            self.residuals.data_ptr(), self.params[band].data_ptr(),
            grad_address)


def _weights_of(params: Sequence[Tensor], bands: int
                ) -> List[List[Tuple[Tensor, Tensor]]]:
    """``[W_1, b_1, ...]``, band after band, as per band, per layer
    ``(weight, bias)``."""
    per_band = len(params) // bands if bands else 0
    return [[(params[first + i], params[first + i + 1])
             for i in range(0, per_band, 2)]
            for first in range(0, len(params), per_band or 1)]


FORWARD_OP = 'wgse_mmseg::compiled_band_networks'
BACKWARD_OP = 'wgse_mmseg::compiled_band_networks_backward'
# Defined as the torch kernel's ops are (:mod:`.torch_band_networks`: no
# torch._dynamo import at their first call).
torch.library.define(FORWARD_OP, '(Tensor coeffs, int[] lengths, '
                     'int[] residuals, Tensor[] params) -> Tensor')
torch.library.define(BACKWARD_OP, '(Tensor grad_out, Tensor coeffs, '
                     'int[] lengths, int[] residuals, Tensor[] params) '
                     '-> Tensor[]')


@torch.library.impl(FORWARD_OP, 'cpu')
def _forward_op(coeffs: Tensor, lengths: List[int], residuals: List[int],
                params: List[Tensor]) -> Tensor:
    """The kernel's forward pass as a torch custom op: ``coeffs`` ``(N,
    C)`` contiguous, ``residuals`` with ``-1`` for none, ``params``
    ``[W_1, b_1, ...]`` band after band; ``(N, C)`` out. ``torch.compile``
    sees one opaque call (no graph break)."""
    bands = _Bands(coeffs, lengths, _weights_of(params, len(lengths)),
                   residual_plan(residuals))
    out = torch.empty_like(coeffs)
    for_each_on_threads(lambda chunk, _: bands.run(chunk, out=out),
                        len(bands.chunks), lambda: None)
    return out


@torch.library.register_fake(FORWARD_OP)
def _forward_fake(coeffs, lengths, residuals, params):
    return torch.empty_like(coeffs)


@torch.library.impl(BACKWARD_OP, 'cpu')
def _backward_op(grad_out: Tensor, coeffs: Tensor, lengths: List[int],
                 residuals: List[int], params: List[Tensor]
                 ) -> List[Tensor]:
    """The kernel's backward pass of :func:`_forward_op` (activations
    recomputed group by group): the parameters' gradients, in their
    order, shapes and dtypes."""
    weights = _weights_of(params, len(lengths))
    bands = _Bands(coeffs, lengths, weights, residual_plan(residuals))
    grad_out = grad_out.contiguous()
    groups = chunk_groups(len(bands.chunks))
    flat = torch.zeros(bands.grad_total, dtype=torch.float64)

    def add(part) -> None:
        where, sums = part
        flat[where] += sums

    # each group's sums over its own bands only (a group is a few chunks,
    # most often of one band), added in group order
    add_in_order = InOrder(add)

    def backward_group(group: int, _) -> None:
        where = bands.grad_range(groups[group])
        sums = torch.zeros(where.stop - where.start, dtype=torch.float64)
        for chunk in groups[group]:
            bands.run(chunk, grad_out=grad_out, grads=sums,
                      grads_start=where.start)
        add_in_order(group, (where, sums))

    for_each_on_threads(backward_group, len(groups), lambda: None)
    grads = []
    for band, where in zip(weights, bands.grad_slices):
        grads += _unpack_grads(flat[where], band)
    return grads


@torch.library.register_fake(BACKWARD_OP)
def _backward_fake(grad_out, coeffs, lengths, residuals, params):
    return [torch.empty_like(p) for p in params]


def _setup_context(ctx, inputs, output) -> None:
    coeffs, lengths, residuals, params = inputs
    ctx.lengths, ctx.residuals = lengths, residuals
    ctx.save_for_backward(coeffs, *params)


def _backward(ctx, grad_out: Tensor):
    coeffs, *params = ctx.saved_tensors
    if torch.is_grad_enabled():  # create_graph=True: second order
        grads = differentiable_backward(
            grad_out, coeffs, params,
            [False] + list(ctx.needs_input_grad[3]), ctx.lengths,
            residual_plan(ctx.residuals), KERNEL_SIZE // 2)
        return None, None, None, grads[1:]
    return None, None, None, \
        torch.ops.wgse_mmseg.compiled_band_networks_backward(
            grad_out, coeffs, ctx.lengths, ctx.residuals, params)


torch.library.register_autograd(FORWARD_OP, _backward,
                                setup_context=_setup_context)


def compiled_band_networks(coeffs: Tensor, lengths: Sequence[int],
                           weights: Sequence[Sequence[Tuple[Tensor,
                                                            Tensor]]],
                           residuals: Sequence[Optional[int]]) -> Tensor:
    """Run one temporal CNN per band over every pixel's coefficients.

    Arguments and result as
    :func:`~wgse_mmseg.core.wgse.torch_band_networks.torch_band_networks`
    (``coeffs`` ``(N, C)``, bands side by side); only where
    :func:`unsupported` returns ``None``. Gradients flow to the parameters, not
    to ``coeffs``.
    """
    reason = unsupported(coeffs, weights, residuals)
    if reason:
        raise ValueError(f'the compiled band network kernel does not apply '
                         f'here: {reason}')
    if len(weights) != len(lengths) or sum(lengths) != coeffs.shape[1]:
        raise ValueError(
            f'{len(weights)} band networks and bands of lengths {lengths} '
            f'do not fit coefficients shaped {tuple(coeffs.shape)}')
    params = [t for band in weights for layer in band for t in layer]
    return torch.ops.wgse_mmseg.compiled_band_networks(
        coeffs.contiguous(), list(lengths),
        op_residuals(residuals), params)
