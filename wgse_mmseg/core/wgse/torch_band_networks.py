"""The 1-D band networks of WGSE as one fused, chunked torch kernel: the
``'torch'`` backend of WGSE on the CPU.

:class:`~wgse_mmseg.core.wgse.band_network.BandNetwork` with ``dim=1`` runs a
few tiny temporal convolutions (1 -> 32 -> 32 -> 1 channels, kernel 3) over
every pixel's wavelet coefficients. As ``nn.Conv1d`` over ``B*H*W`` signals of
15-72 samples this spends its time moving data, not multiplying. Here each
convolution is a few matrix products on a "padded rows" layout instead
(:mod:`~wgse_mmseg.core.wgse.row_convolutions`):

* chunks of a band's pixels are sized so that a layer's activations stay in
  cache, and every buffer is reused from chunk to chunk
  (:class:`~wgse_mmseg.core.wgse.row_convolutions.Workspace`);
* with several torch threads, whole chunks run side by side, one per
  thread (:func:`~wgse_mmseg.core.parallel.for_each_on_threads`), instead
  of splitting each small product.

This is the CPU's kernel: off the CPU the ``'torch'`` backend runs the
device library's convolutions instead
(:mod:`~wgse_mmseg.core.wgse.band_network_backends`), since many small
products per chunk are the opposite of what a GPU wants.

The backward pass is written out by hand on the same layout. It keeps no
activation: each chunk's are recomputed in the backward pass (activation
checkpointing at chunk granularity: no activation of size ``B*H*W*C*32``
outlives the forward pass, for about a third more arithmetic).

The result equals ``BandNetwork`` applied per pixel (tests compare both, and
``gradcheck`` the gradients in float64), and depends neither on timing nor
on the thread count: parameter gradients are summed over fixed groups of
chunks (:func:`chunk_groups`, whatever thread runs a group) and the groups
added in order.

Second-order gradients (a backward pass with ``create_graph=True``, as a
gradient penalty takes): the hand-written backward keeps no graph, so there
it runs :func:`differentiable_backward` instead, torch's own convolutions
on the whole input, whose gradients are differentiable again (memory as the
``'reference'`` backend's).
"""
import threading
from typing import (Any, Callable, Dict, Iterator, List, NamedTuple, Optional,
                    Sequence, Tuple)

import torch
import torch.nn.functional as F
from torch import Tensor

from ..parallel import for_each_on_threads
from .row_convolutions import (Layer, Workspace, chunk_backward,
                               chunk_forward, zero_grads)

__all__ = []

#: Rows (pixel-coefficients) per chunk: 16384 rows x 32 channels x 4 bytes
#: is 2 MiB per activation, so a chunk's layers stay in the L2/L3 caches
#: while each product is still long enough to hide the per-call overhead
#: (docs/wgse_speed.md has the chunk sizes measured).
ROWS_PER_CHUNK = 16384
#: most groups of chunks whose parameter gradients are summed apart
#: (:func:`chunk_groups`): bounds the partial sums kept
MAX_GROUPS = 64


def chunk_groups(count: int) -> List[range]:
    """Chunks ``0 .. count-1`` in consecutive groups, at most
    :data:`MAX_GROUPS`, fixed by ``count`` alone: a group's gradient sum,
    and the sum of the groups in order, come out the same whatever thread
    runs which group and however many there are."""
    size = max(1, -(-count // MAX_GROUPS))
    return [range(first, min(first + size, count))
            for first in range(0, count, size)]


class InOrder:
    """Parts numbered ``0, 1, ...``, handed in by any thread in any order,
    passed to ``add(part)`` in their numbers' order, each as soon as all
    before it are in: the groups' gradient sums added in group order (the
    same bits whatever the threads) with only the parts that came early
    held, not every group's."""

    def __init__(self, add: Callable[[Any], None]):
        self._add = add
        self._waiting: Dict[int, Any] = {}
        self._next = 0
        self._lock = threading.Lock()

    def __call__(self, index: int, part: Any) -> None:
        with self._lock:
            self._waiting[index] = part
            while self._next in self._waiting:
                self._add(self._waiting.pop(self._next))
                self._next += 1


def _modules_forward(coeffs: Tensor, lengths: Sequence[int],
                     residuals: Sequence[Optional[int]], pad: int,
                     params: Sequence[Tensor]) -> Tensor:
    """The band networks as torch convolutions on ``(N, C)`` coefficients
    (the function of :func:`torch_band_networks`, differentiable to any
    order, every activation kept)."""
    per_band = 2 * len(residuals)
    outs = []
    for index, band in enumerate(coeffs.split(list(lengths), dim=1)):
        acts = [band.unsqueeze(1)]  # (N, 1, L)
        for layer, residual in enumerate(residuals):
            first = index * per_band + 2 * layer
            x = F.conv1d(acts[-1], params[first], params[first + 1],
                         padding=pad)
            if residual is not None:
                x = x + acts[residual]
            acts.append(F.relu(x))
        outs.append(acts[-1].squeeze(1))
    return torch.cat(outs, 1) if outs else coeffs.clone()


def differentiable_backward(grad_out: Tensor, coeffs: Tensor,
                            params: Sequence[Tensor],
                            needs_input_grad: Sequence[bool],
                            lengths: Sequence[int],
                            residuals: Sequence[Optional[int]], pad: int
                            ) -> List[Optional[Tensor]]:
    """The gradients of the band networks, ``[d coeffs, *d params]``
    (``None`` where ``needs_input_grad`` is false), as a graph that can be
    differentiated again: what a band-network kernel's backward returns
    when called with ``create_graph=True``."""
    wanted = [tensor for tensor, need in zip([coeffs, *params],
                                             needs_input_grad) if need]
    with torch.enable_grad():
        out = _modules_forward(coeffs, lengths, residuals, pad, params)
        found = iter(torch.autograd.grad(out, wanted, grad_out,
                                         create_graph=True,
                                         allow_unused=True))
    return [next(found) if need else None for need in needs_input_grad]


def op_residuals(plan: Sequence[Optional[int]]) -> List[int]:
    """A residual plan ``(index or None, ...)`` as the custom ops'
    ``int[]`` (``-1``: none); :func:`residual_plan` reads it back."""
    return [-1 if r is None else r for r in plan]


def residual_plan(residuals: Sequence[int]) -> Tuple[Optional[int], ...]:
    """The custom ops' ``int[]`` residual plan (``-1``: none) as the
    kernels' ``(index or None, ...)``."""
    return tuple(None if r < 0 else r for r in residuals)


FORWARD_OP = 'wgse_mmseg::torch_band_networks'
BACKWARD_OP = 'wgse_mmseg::torch_band_networks_backward'
# The custom ops, defined with the library's lower-level calls rather than
# torch.library.custom_op, whose kernels import torch._dynamo on their first
# call (seconds, 70 MiB); torch.library.impl's do not (dynamo never traces
# into an op's kernel; it calls it).
torch.library.define(FORWARD_OP, '(Tensor coeffs, int[] lengths, '
                     'int[] residuals, int pad, Tensor[] params) -> Tensor')
torch.library.define(BACKWARD_OP, '(Tensor grad_out, Tensor coeffs, '
                     'int[] lengths, int[] residuals, int pad, '
                     'Tensor[] params, bool input_grad) -> Tensor[]')


@torch.library.impl(FORWARD_OP, 'cpu')
def _forward_op(coeffs: Tensor, lengths: List[int], residuals: List[int],
                pad: int, params: List[Tensor]) -> Tensor:
    """The forward pass of :func:`torch_band_networks` as a torch custom
    op: ``coeffs`` ``(N, C)`` contiguous, ``residuals`` with ``-1`` for
    none, ``params`` ``[W_1, b_1, ...]`` band after band; ``(N, C)`` out.
    ``torch.compile`` sees one opaque call (no graph break) whose output
    shape :func:`_forward_fake` gives."""
    out = torch.empty_like(coeffs)
    chunks = list(_chunks(coeffs, tuple(lengths), residual_plan(residuals),
                          pad, params))

    def forward_chunk(chunk: int, scratch: Workspace) -> None:
        band, columns, rows, layers = chunks[chunk]
        seg_len = band.length + 2 * pad
        acts = chunk_forward(columns[rows], layers, pad, scratch)
        out[rows, band.offset] = acts[-1].view(
            -1, seg_len)[:, pad:pad + band.length]

    for_each_on_threads(forward_chunk, len(chunks),
                        lambda: Workspace(coeffs))
    return out


@torch.library.register_fake(FORWARD_OP)
def _forward_fake(coeffs, lengths, residuals, pad, params):
    return torch.empty_like(coeffs)


@torch.library.impl(BACKWARD_OP, 'cpu')
def _backward_op(grad_out: Tensor, coeffs: Tensor, lengths: List[int],
                 residuals: List[int], pad: int, params: List[Tensor],
                 input_grad: bool) -> List[Tensor]:
    """The hand-written backward pass of :func:`_forward_op` (each chunk's
    activations recomputed): ``[d coeffs (N, C), *d params]``, without
    ``d coeffs`` unless ``input_grad``."""
    plan = residual_plan(residuals)
    grad_coeffs = torch.zeros_like(coeffs) if input_grad else None
    grad_out = grad_out.contiguous()
    per_band = 2 * len(plan)
    chunks = list(_chunks(coeffs, tuple(lengths), plan, pad, params))
    groups = chunk_groups(len(chunks))
    param_grads = zero_grads(params)

    def add(part: List[Optional[Tensor]]) -> None:
        for total, grad in zip(param_grads, part):
            if grad is not None:
                total += grad

    # each group's sums for its own bands only (``None`` for the others: a
    # group is a few chunks, most often of one band), added in group order
    add_in_order = InOrder(add)

    def backward_group(group: int, scratch: Workspace) -> None:
        part: List[Optional[Tensor]] = [None] * len(params)
        for chunk in groups[group]:
            band, columns, rows, layers = chunks[chunk]
            first = band.index * per_band
            if part[first] is None:
                part[first:first + per_band] = zero_grads(
                    params[first:first + per_band])
            acts = chunk_forward(columns[rows], layers, pad, scratch)
            grad_in = chunk_backward(
                acts, grad_out[rows, band.offset], layers,
                part[first:first + per_band], pad, input_grad, scratch)
            if input_grad:
                grad_coeffs[rows, band.offset] = grad_in
        add_in_order(group, part)

    for_each_on_threads(backward_group, len(groups),
                        lambda: Workspace(coeffs))
    param_grads = [g.permute(2, 1, 0).contiguous() if g.dim() == 3 else g
                   for g in param_grads]
    return ([grad_coeffs] if input_grad else []) + param_grads


@torch.library.register_fake(BACKWARD_OP)
def _backward_fake(grad_out, coeffs, lengths, residuals, pad, params,
                   input_grad):
    return [torch.empty_like(t) for t in ([coeffs] if input_grad else [])
            + list(params)]


def _setup_context(ctx, inputs, output) -> None:
    coeffs, lengths, residuals, pad, params = inputs
    ctx.lengths, ctx.residuals, ctx.pad = lengths, residuals, pad
    ctx.save_for_backward(coeffs, *params)


def _backward(ctx, grad_out: Tensor):
    coeffs, *params = ctx.saved_tensors
    input_grad = ctx.needs_input_grad[0]
    if torch.is_grad_enabled():  # create_graph=True: second order
        grads = differentiable_backward(
            grad_out, coeffs, params,
            [input_grad] + list(ctx.needs_input_grad[4]), ctx.lengths,
            residual_plan(ctx.residuals), ctx.pad)
        return grads[0], None, None, None, grads[1:]
    grads = torch.ops.wgse_mmseg.torch_band_networks_backward(
        grad_out, coeffs, ctx.lengths, ctx.residuals, ctx.pad, params,
        input_grad)
    grad_coeffs = grads.pop(0) if input_grad else None
    return grad_coeffs, None, None, None, grads


torch.library.register_autograd(FORWARD_OP, _backward,
                                setup_context=_setup_context)


class _Band(NamedTuple):
    """One band's column range in the ``(N, C)`` coefficients."""
    index: int
    offset: slice
    length: int


def _chunks(coeffs: Tensor, lengths: Tuple[int, ...],
            residuals: Tuple[Optional[int], ...], pad: int,
            params: Sequence[Tensor]
            ) -> Iterator[Tuple[_Band, Tensor, slice, List[Layer]]]:
    """Yield ``(band, its columns (N, L), pixel rows, its layers)`` for
    every cache-sized chunk of every band."""
    per_band = 2 * len(residuals)
    start = 0
    for index, length in enumerate(lengths):
        first = index * per_band
        layers = [Layer.from_conv(params[first + 2 * i],
                                  params[first + 2 * i + 1], residual)
                  for i, residual in enumerate(residuals)]
        band = _Band(index, slice(start, start + length), length)
        columns = coeffs[:, band.offset]
        step = max(1, ROWS_PER_CHUNK // (length + 2 * pad))
        for row in range(0, coeffs.shape[0], step):
            yield band, columns, slice(row, row + step), layers
        start += length


def torch_band_networks(coeffs: Tensor, lengths: Sequence[int],
                        weights: Sequence[Sequence[Tuple[Tensor, Tensor]]],
                        residuals: Sequence[Optional[int]]) -> Tensor:
    """Run one temporal CNN per band over every pixel's coefficients.

    Args:
        coeffs: ``(N, C)`` coefficients of ``N`` pixels, the bands side by
            side (``C = sum(lengths)``), float32 or float64, on the CPU.
        lengths: ``L`` of each band.
        weights: per band, per layer, ``(weight (C_out, C_in, k), bias
            (C_out,))``; every layer is a 'same'-padded 1-D convolution
            followed by ReLU, the first has ``C_in = 1`` and the last
            ``C_out = 1``; the same structure for every band.
        residuals: per layer, the index of the activation added before its
            ReLU (0 is the band's input, ``i`` the output of layer ``i``;
            a 1-channel activation broadcasts), or ``None``.

    Returns:
        ``(N, C)``: each band's network output, in place of its input.
    """
    if coeffs.device.type != 'cpu':
        raise ValueError(f'torch_band_networks runs CPU tensors, got '
                         f'{coeffs.device} coefficients (the torch backend '
                         f'runs nn.Conv1d chunks elsewhere)')
    if len(weights) != len(lengths) or sum(lengths) != coeffs.shape[1]:
        raise ValueError(
            f'{len(weights)} band networks and bands of lengths {lengths} '
            f'do not fit coefficients shaped {tuple(coeffs.shape)}')
    kernel_size = weights[0][0][0].shape[2]
    params = [t for band in weights for layer in band for t in layer]
    return torch.ops.wgse_mmseg.torch_band_networks(
        coeffs.contiguous(), list(lengths),
        op_residuals(residuals), kernel_size // 2,
        params)
