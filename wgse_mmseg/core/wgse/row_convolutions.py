"""Convolutions as matrix products on the "padded rows" layout: the
arithmetic of the ``'torch'`` band-network kernel
(:mod:`~wgse_mmseg.core.wgse.torch_band_networks`).

A chunk of ``n`` pixels of one band is a ``(n * S, C)`` matrix, pixel-major,
each pixel's ``L`` coefficients surrounded by ``p = k // 2`` zero rows
(``S = L + 2p``), channels last. A 'same'-padded Conv1d is then one product
per tap on shifted, contiguous row ranges (a 1-channel side is unfolded
instead, for a single product), the bias added in the first ``addmm``; rows
that straddle two pixels only ever see the zero padding of both, and are
reset to zero afterwards. :func:`chunk_forward` runs a chunk through a band
network's layers, :func:`chunk_backward` is its backward pass written out on
the same layout; every buffer comes from a :class:`Workspace` reused from
chunk to chunk.
"""
from typing import Dict, List, NamedTuple, Optional, Sequence

import torch
from torch import Tensor

__all__ = []


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


class Workspace:
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


def im2col(rows: Tensor, kernel_size: int, scratch: Workspace) -> Tensor:
    """``(R, C)`` -> ``(R - k + 1, k * C)``: row ``r`` is rows ``r..r+k-1``."""
    count, channels = rows.shape
    shape = (count - kernel_size + 1, kernel_size * channels)
    return scratch('im2col', *shape).copy_(
        rows.as_strided(shape, (channels, 1)))


def diagonal(per_tap: Tensor, count: int) -> Tensor:
    """``(k, count + k - 1)`` -> the ``(count, k)`` view
    ``[r, j] = per_tap[j, r + j]``."""
    return per_tap.as_strided((count, per_tap.shape[0]),
                              (1, per_tap.shape[1] + 1))


def conv_rows(src: Tensor, taps: Tensor, out: Tensor, scratch: Workspace,
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
        columns = im2col(src, kernel_size, scratch)
        if bias is None:
            torch.mm(columns, matrix, out=out)
        else:
            torch.addmm(bias, columns, matrix, out=out)
    elif out_channels == 1:
        per_tap = torch.mm(taps.view(kernel_size, channels), src.t(),
                           out=scratch('per_tap', kernel_size, src.shape[0]))
        torch.sum(diagonal(per_tap, count), 1, keepdim=True, out=out)
        if bias is not None:
            out += bias
    else:
        if bias is None:
            torch.mm(src[:count], taps[0], out=out)
        else:
            torch.addmm(bias, src[:count], taps[0], out=out)
        for tap in range(1, kernel_size):
            out.addmm_(src[tap:tap + count], taps[tap])


def accumulate_weight_grad(src: Tensor, grad: Tensor, weight_grad: Tensor,
                           scratch: Workspace) -> None:
    """``weight_grad[j] += src[j:j+n].T @ grad`` (``(k, C_in, C_out)``),
    as one product where either side has a single channel."""
    count = grad.shape[0]
    kernel_size, channels, out_channels = weight_grad.shape
    if channels == 1:
        weight_grad.view(kernel_size, out_channels).addmm_(
            im2col(src, kernel_size, scratch).t(), grad)
    elif out_channels == 1:
        # shifted[j, r + j] = grad[r]: then shifted @ src is every tap
        # (as (k, C_in): a k-column result is several times slower).
        shifted = scratch('shifted', kernel_size, src.shape[0]).zero_()
        diagonal(shifted, count).copy_(grad.expand(count, kernel_size))
        weight_grad.view(kernel_size, channels).addmm_(shifted, src)
    else:
        for tap in range(kernel_size):
            weight_grad[tap].addmm_(src[tap:tap + count].t(), grad)


def zero_padding(rows: Tensor, seg_len: int, pad: int) -> None:
    """Reset the ``pad`` rows on both sides of every pixel to zero."""
    if pad:
        segments = rows.view(-1, seg_len, rows.shape[1])
        segments[:, :pad] = 0
        segments[:, seg_len - pad:] = 0


def padded_rows(signals: Tensor, pad: int, out: Tensor) -> Tensor:
    """``(n, L)`` -> ``out`` ``(n * S, 1)``: each pixel's signal between
    zero rows."""
    count, length = signals.shape
    padded = out.view(count, length + 2 * pad)
    padded[:, pad:pad + length] = signals
    zero_padding(out, length + 2 * pad, pad)
    return out


def chunk_forward(signals: Tensor, layers: Sequence[Layer], pad: int,
                  scratch: Workspace) -> List[Tensor]:
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
    acts = [padded_rows(signals, pad, scratch(('act', 0), rows, 1))]
    for index, layer in enumerate(layers, 1):
        out = scratch(('act', index), rows, layer.taps.shape[2])
        interior = out[pad:rows - pad]
        conv_rows(acts[index - 1], layer.taps, interior, scratch,
                  layer.bias)
        if layer.residual is not None:
            interior += acts[layer.residual][pad:rows - pad]
        out.relu_()
        zero_padding(out, seg_len, pad)
        acts.append(out)
    return acts


def chunk_backward(acts: List[Tensor], grad_out: Tensor,
                   layers: Sequence[Layer], param_grads: List[Tensor],
                   pad: int, need_input_grad: bool,
                   scratch: Workspace) -> Optional[Tensor]:
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
    grad = padded_rows(grad_out, pad,
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
        accumulate_weight_grad(acts[index], grad[pad:rows - pad],
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
        conv_rows(grad, layers[index].back_taps, grad_in[pad:rows - pad],
                  scratch)
        if index in pending:
            grad_in += pending.pop(index)
        grad = grad_in
    return grad.view(count, seg_len)[:, pad:pad + length]


def zero_grads(params: Sequence[Tensor]) -> List[Tensor]:
    """Zeros for every parameter; weights as ``(k, C_in, C_out)``, the
    taps' layout, in which their gradients accumulate."""
    return [p.new_zeros(p.permute(2, 1, 0).shape) if p.dim() == 3
            else torch.zeros_like(p) for p in params]
