"""The 1-D band networks of WGSE as one fused, chunked torch kernel: the
``'torch'`` backend of WGSE on the CPU.

:class:`~wgse_mmseg.core.wgse.band_network.BandNetwork` with ``dim=1`` runs a
few tiny temporal convolutions (1 -> 32 -> 32 -> 1 channels, kernel 3) over
every pixel's wavelet coefficients. As ``nn.Conv1d`` over ``B*H*W`` signals of
15-72 samples this spends its time moving data, not multiplying. Here each
convolution is a few matrix products on a "padded rows" layout instead:

* a chunk of ``n`` pixels of one band is a ``(n * S, C)`` matrix, pixel-major,
  each pixel's ``L`` coefficients surrounded by ``p = k // 2`` zero rows
  (``S = L + 2p``), channels last;
* a convolution is then one product per tap on shifted, contiguous row
  ranges (a 1-channel side is unfolded instead, for a single product), bias
  added in the first ``addmm``; rows that straddle two pixels only ever see
  the zero padding of both, and are reset to zero afterwards;
* chunks are sized so that a layer's activations stay in cache, and every
  buffer is reused from chunk to chunk (:class:`_Workspace`);
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

__all__ = []

#: Rows (pixel-coefficients) per chunk: 16384 rows x 32 channels x 4 bytes
#: is 2 MiB per activation, so a chunk's layers stay in the L2/L3 caches
#: while each product is still long enough to hide the per-call overhead
#: (docs/wgse_speed.md has the chunk sizes measured).
ROWS_PER_CHUNK = 16384


class Layer(NamedTuple):
    """One convolution, its weights laid out for the row products."""
    taps: Tensor  # (k, C_in, C_out): the forward taps
    back_taps: Tensor  # (k, C_out, C_in): flipped, for the input gradient
    bias: Tensor  # (C_out,)
    residual: Optional[int]  # activation added before the ReLU (0: input)

    @classmethod
    def from_conv(cls, weight: Tensor, bias: Tensor,
                  residual: Optional[int]) -> 'Layer':
        """From a ``(C_out, C_in, k)`` Conv1d weight."""
        return cls(weight.permute(2, 1, 0).contiguous(),
                   weight.flip(2).permute(2, 0, 1).contiguous(), bias,
                   residual)


class _Workspace:
    """Buffers reused from chunk to chunk, one per role.

    A fresh ``(rows, 32)`` activation per chunk and layer is 2 MiB that the
    kernel faults in on first touch, a cost of the order of the arithmetic
    that fills it; so each role (``('act', i)``, ``('grad', i)``,
    ``'im2col'``, ...) gets one buffer, grown to the largest chunk.
    """

    def __init__(self, like: Tensor):
        self._like = like
        self._flat: Dict[object, Tensor] = {}

    def __call__(self, role: object, rows: int, columns: int) -> Tensor:
        """A ``(rows, columns)`` buffer for ``role``, contents undefined."""
        size = rows * columns
        flat = self._flat.get(role)
        if flat is None or flat.numel() < size:
            flat = self._flat[role] = self._like.new_empty(size)
        return flat[:size].view(rows, columns)


def _im2col(rows: Tensor, kernel_size: int, scratch: _Workspace) -> Tensor:
    """``(R, C)`` -> ``(R - k + 1, k * C)``: row ``r`` is rows ``r..r+k-1``."""
    count, channels = rows.shape
    shape = (count - kernel_size + 1, kernel_size * channels)
    return scratch('im2col', *shape).copy_(
        rows.as_strided(shape, (channels, 1)))


def _diagonal(per_tap: Tensor, count: int) -> Tensor:
    """``(k, count + k - 1)`` -> the ``(count, k)`` view
    ``[r, j] = per_tap[j, r + j]``."""
    return per_tap.as_strided((count, per_tap.shape[0]),
                              (1, per_tap.shape[1] + 1))


def _conv_rows(src: Tensor, taps: Tensor, out: Tensor, scratch: _Workspace,
               bias: Optional[Tensor] = None) -> None:
    """``out[r] = bias + sum_j src[r + j] @ taps[j]`` for every row of ``out``.

    Args:
        src: ``(R, C_src)`` rows; ``out`` has ``R - k + 1`` rows.
        taps: ``(k, C_src, C_dst)``, contiguous.
        out: ``(R - k + 1, C_dst)``, contiguous, written in place.

    Every form reads ``src`` once or, for wide layers, ``k`` times from
    contiguous views, and copies nothing wide:

    * 1-channel source: unfold it (``im2col``, ``k`` columns), one product;
    * 1-channel output: one product giving every tap's response as a row
      (``(k, R)``: MKL is several times slower with a ``k``-column result),
      then the sum of the shifted diagonal ``y[j, r + j]``;
    * otherwise tap by tap, each a product on a shifted row range.
    """
    kernel_size, channels, out_channels = taps.shape
    count = out.shape[0]
    if channels == 1:
        matrix = taps.view(kernel_size, out_channels)
        columns = _im2col(src, kernel_size, scratch)
        if bias is None:
            torch.mm(columns, matrix, out=out)
        else:
            torch.addmm(bias, columns, matrix, out=out)
    elif out_channels == 1:
        per_tap = torch.mm(taps.view(kernel_size, channels), src.t(),
                           out=scratch('per_tap', kernel_size, src.shape[0]))
        torch.sum(_diagonal(per_tap, count), 1, keepdim=True, out=out)
        if bias is not None:
            out += bias
    else:
        if bias is None:
            torch.mm(src[:count], taps[0], out=out)
        else:
            torch.addmm(bias, src[:count], taps[0], out=out)
        for tap in range(1, kernel_size):
            out.addmm_(src[tap:tap + count], taps[tap])


def _accumulate_weight_grad(src: Tensor, grad: Tensor, weight_grad: Tensor,
                            scratch: _Workspace) -> None:
    """``weight_grad[j] += src[j:j+n].T @ grad`` (``(k, C_in, C_out)``),
    as one product where either side has a single channel."""
    count = grad.shape[0]
    kernel_size, channels, out_channels = weight_grad.shape
    if channels == 1:
        weight_grad.view(kernel_size, out_channels).addmm_(
            _im2col(src, kernel_size, scratch).t(), grad)
    elif out_channels == 1:
        # shifted[j, r + j] = grad[r]: then shifted @ src is every tap
        # (as (k, C_in): a k-column result is several times slower).
        shifted = scratch('shifted', kernel_size, src.shape[0]).zero_()
        _diagonal(shifted, count).copy_(grad.expand(count, kernel_size))
        weight_grad.view(kernel_size, channels).addmm_(shifted, src)
    else:
        for tap in range(kernel_size):
            weight_grad[tap].addmm_(src[tap:tap + count].t(), grad)


def _zero_padding(rows: Tensor, seg_len: int, pad: int) -> None:
    """Reset the ``pad`` rows on both sides of every pixel to zero."""
    if pad:
        segments = rows.view(-1, seg_len, rows.shape[1])
        segments[:, :pad] = 0
        segments[:, seg_len - pad:] = 0


def _padded_rows(signals: Tensor, pad: int, out: Tensor) -> Tensor:
    """``(n, L)`` -> ``out`` ``(n * S, 1)``: each pixel's signal between
    zero rows."""
    count, length = signals.shape
    padded = out.view(count, length + 2 * pad)
    padded[:, pad:pad + length] = signals
    _zero_padding(out, length + 2 * pad, pad)
    return out


def _chunk_forward(signals: Tensor, layers: Sequence[Layer], pad: int,
                   scratch: _Workspace) -> List[Tensor]:
    """All activations of one chunk, in ``scratch``'s buffers (valid until
    the next chunk).

    Args:
        signals: ``(n, L)`` coefficients of ``n`` pixels.

    Returns:
        ``[input, act_1, ..., act_m]``, each ``(n * S, C)`` with zero padding.
    """
    count, length = signals.shape
    seg_len = length + 2 * pad
    rows = count * seg_len
    acts = [_padded_rows(signals, pad, scratch(('act', 0), rows, 1))]
    for index, layer in enumerate(layers, 1):
        out = scratch(('act', index), rows, layer.taps.shape[2])
        interior = out[pad:rows - pad]
        _conv_rows(acts[index - 1], layer.taps, interior, scratch,
                   layer.bias)
        if layer.residual is not None:
            interior += acts[layer.residual][pad:rows - pad]
        out.relu_()
        _zero_padding(out, seg_len, pad)
        acts.append(out)
    return acts


def _chunk_backward(acts: List[Tensor], grad_out: Tensor,
                    layers: Sequence[Layer], param_grads: List[Tensor],
                    pad: int, need_input_grad: bool,
                    scratch: _Workspace) -> Optional[Tensor]:
    """Accumulate one chunk's parameter gradients into ``param_grads``
    (``[dW_1, db_1, dW_2, ...]``, each ``dW`` as ``(k, C_in, C_out)``).

    Args:
        grad_out: ``(n, L)`` gradient of the band output.

    Returns:
        ``(n, L)`` gradient of the band input (valid until the next chunk),
        or ``None``.
    """
    count, length = grad_out.shape
    seg_len = length + 2 * pad
    rows = count * seg_len
    grad = _padded_rows(grad_out, pad,
                        scratch(('grad', len(layers)), rows, 1))
    pending = {}  # activation index -> gradient reaching it via a residual
    for index in range(len(layers) - 1, -1, -1):
        residual = layers[index].residual
        # ReLU backward, in place; activations are zero on padding rows, so
        # is grad.
        torch.ops.aten.threshold_backward.grad_input(
            grad, acts[index + 1], 0, grad_input=grad)
        if residual is not None and (residual > 0 or need_input_grad):
            skip = grad if acts[residual].shape[1] > 1 else grad.sum(
                1, keepdim=True)
            pending[residual] = pending.get(residual, 0) + skip
        param_grads[2 * index + 1] += grad.sum(0)
        _accumulate_weight_grad(acts[index], grad[pad:rows - pad],
                                param_grads[2 * index], scratch)
        if index == 0 and not need_input_grad:
            return None
        # Rows on the padding get values here, but the next ReLU backward
        # (or, for the input, the slice below) discards them. Written into
        # the buffer of this layer's output, which nothing reads any more
        # (its ReLU backward is done): one activation-sized buffer less
        # than a buffer per gradient.
        grad_in = scratch(('act', index + 1), rows,
                          layers[index].taps.shape[1])
        grad_in[:pad] = grad_in[rows - pad:] = 0
        _conv_rows(grad, layers[index].back_taps, grad_in[pad:rows - pad],
                   scratch)
        if index in pending:
            grad_in += pending.pop(index)
        grad = grad_in
    return grad.view(count, seg_len)[:, pad:pad + length]


def _zero_grads(params: Sequence[Tensor]) -> List[Tensor]:
    """Zeros for every parameter; weights as ``(k, C_in, C_out)``, the
    taps' layout, in which their gradients accumulate."""
    return [p.new_zeros(p.permute(2, 1, 0).shape) if p.dim() == 3
            else torch.zeros_like(p) for p in params]


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

    def forward_chunk(chunk: int, scratch: _Workspace) -> None:
        band, columns, rows, layers = chunks[chunk]
        seg_len = band.length + 2 * pad
        acts = _chunk_forward(columns[rows], layers, pad, scratch)
        out[rows, band.offset] = acts[-1].view(
            -1, seg_len)[:, pad:pad + band.length]

    for_each_on_threads(forward_chunk, len(chunks),
                        lambda: _Workspace(coeffs))
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
    param_grads = _zero_grads(params)

    def add(part: List[Optional[Tensor]]) -> None:
        for total, grad in zip(param_grads, part):
            if grad is not None:
                total += grad

    # each group's sums for its own bands only (``None`` for the others: a
    # group is a few chunks, most often of one band), added in group order
    add_in_order = InOrder(add)

    def backward_group(group: int, scratch: _Workspace) -> None:
        part: List[Optional[Tensor]] = [None] * len(params)
        for chunk in groups[group]:
            band, columns, rows, layers = chunks[chunk]
            first = band.index * per_band
            if part[first] is None:
                part[first:first + per_band] = _zero_grads(
                    params[first:first + per_band])
            acts = _chunk_forward(columns[rows], layers, pad, scratch)
            grad_in = _chunk_backward(
                acts, grad_out[rows, band.offset], layers,
                part[first:first + per_band], pad, input_grad, scratch)
            if input_grad:
                grad_coeffs[rows, band.offset] = grad_in
        add_in_order(group, part)

    for_each_on_threads(backward_group, len(groups),
                        lambda: _Workspace(coeffs))
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
