"""The 1-D band networks of WGSE as one fused, cache-blocked CPU kernel.

:class:`~wgse_mmseg.models.wgse.BandNetwork` with ``dim=1`` runs a few tiny
temporal convolutions (1 -> 32 -> 32 -> 1 channels, kernel 3) over every
pixel's wavelet coefficients. As ``nn.Conv1d`` over ``B*H*W`` signals of
15-72 samples this spends its time moving data, not multiplying. Here each
convolution is one matrix product on a "padded rows" layout instead:

* a chunk of ``n`` pixels of one band is a ``(n * S, C)`` matrix, pixel-major,
  each pixel's ``L`` coefficients surrounded by ``p = k // 2`` zero rows
  (``S = L + 2p``), channels last;
* a convolution is then ``im2col`` (a strided view of ``k`` consecutive
  rows, copied once) times a ``(k * C_in, C_out)`` weight matrix, bias added
  in the same ``addmm``; rows that straddle two pixels only ever see the zero
  padding of both, and are reset to zero afterwards;
* chunks are sized so that a layer's activations stay in cache.

The backward pass is written out by hand on the same layout. It keeps only
the outputs of the wide (32 -> 32) convolutions between forward and backward
and recomputes the cheap ones (the 1 -> 32 input and 32 -> 1 output layers:
a ``k``-column product each), which halves the memory of keeping all;
``recompute=True`` keeps nothing and recomputes each chunk in the backward
pass (activation checkpointing at chunk granularity: no activation of size
``B*H*W*C*32`` outlives the forward pass, for a third more arithmetic).

The result equals ``BandNetwork`` applied per pixel (tests compare both, and
``gradcheck`` the gradients in float64).
"""
from typing import Dict, Iterator, List, NamedTuple, Optional, Sequence, Tuple

import torch
from torch import Tensor

__all__ = ['fused_band_networks', 'ROWS_PER_CHUNK']

#: Rows (pixel-coefficients) per chunk: 16384 rows x 32 channels x 4 bytes
#: is 2 MiB per activation, so a chunk's layers stay in the L2/L3 caches
#: while each product is still long enough to hide the per-call overhead
#: (measured: 8192-32768 rows within 10% of each other on an AMD EPYC,
#: 4096 and 65536 clearly slower).
ROWS_PER_CHUNK = 16384

# A layer: (weight (C_out, C_in, k), bias (C_out,), index of the activation
# added before its ReLU, or None). Activation 0 is the band's input.
Layer = Tuple[Tensor, Tensor, Optional[int]]


def _im2col(rows: Tensor, kernel_size: int) -> Tensor:
    """``(R, C)`` -> ``(R - k + 1, k * C)``: row ``r`` is rows ``r..r+k-1``."""
    count, channels = rows.shape
    return rows.as_strided((count - kernel_size + 1, kernel_size * channels),
                           (channels, 1)).contiguous()


def _conv_rows(src: Tensor, taps: Tensor, out: Tensor,
               bias: Optional[Tensor] = None) -> None:
    """``out[r] = bias + sum_j src[r + j] @ taps[j]`` for every row of ``out``.

    Args:
        src: ``(R, C_src)`` rows; ``out`` has ``R - k + 1`` rows.
        taps: ``(k, C_src, C_dst)``.
        out: ``(R - k + 1, C_dst)``, contiguous, written in place.

    A 1-channel source is unfolded (``im2col``, ``k`` columns) for one
    product; a wide one is multiplied tap by tap on shifted row ranges,
    which are contiguous views, so nothing is copied.
    """
    kernel_size, channels = taps.shape[:2]
    if channels == 1:
        matrix = taps.reshape(kernel_size, -1)
        if bias is None:
            torch.mm(_im2col(src, kernel_size), matrix, out=out)
        else:
            torch.addmm(bias, _im2col(src, kernel_size), matrix, out=out)
        return
    count = out.shape[0]
    if bias is None:
        torch.mm(src[:count], taps[0], out=out)
    else:
        torch.addmm(bias, src[:count], taps[0], out=out)
    for tap in range(1, kernel_size):
        out.addmm_(src[tap:tap + count], taps[tap])


def _accumulate_weight_grad(src: Tensor, grad: Tensor,
                            weight_grad: Tensor) -> None:
    """``weight_grad[j] += src[j:j+n].T @ grad`` (``(k, C_in, C_out)``)."""
    count = grad.shape[0]
    for tap in range(weight_grad.shape[0]):
        weight_grad[tap].addmm_(src[tap:tap + count].t(), grad)


def _zero_padding(rows: Tensor, seg_len: int, pad: int) -> None:
    """Reset the ``pad`` rows on both sides of every pixel to zero."""
    if pad:
        segments = rows.view(-1, seg_len, rows.shape[1])
        segments[:, :pad] = 0
        segments[:, seg_len - pad:] = 0


def _padded_rows(signals: Tensor, pad: int) -> Tensor:
    """``(n, L)`` -> ``(n * S, 1)``: each pixel's signal between zero rows."""
    count, length = signals.shape
    padded = signals.new_zeros(count, length + 2 * pad)
    padded[:, pad:pad + length] = signals
    return padded.view(-1, 1)


def _is_wide(weight: Tensor) -> bool:
    """A convolution with ``C_in, C_out > 1``: a full GEMM to recompute."""
    return min(weight.shape[:2]) > 1


def _chunk_forward(signals: Tensor, layers: Sequence[Layer], pad: int,
                   acts: Optional[List[Optional[Tensor]]] = None,
                   stores: Optional[Dict[int, Tensor]] = None
                   ) -> List[Tensor]:
    """All activations of one chunk.

    Args:
        signals: ``(n, L)`` coefficients of ``n`` pixels.
        acts: activations kept from an earlier pass, ``None`` where dropped;
            only the dropped ones are computed again.
        stores: activation index -> ``(n * S, C)`` buffer to write that
            activation into (instead of a fresh tensor).

    Returns:
        ``[input, act_1, ..., act_m]``, each ``(n * S, C)`` with zero padding.
    """
    seg_len = signals.shape[1] + 2 * pad
    if acts is None:
        acts = [_padded_rows(signals, pad)] + [None] * len(layers)
    for index, (weight, bias, residual) in enumerate(layers, 1):
        if acts[index] is not None:
            continue
        rows = acts[index - 1].shape[0]
        out = (stores or {}).get(index)
        if out is None:
            out = signals.new_empty(rows, weight.shape[0])
        interior = out[pad:rows - pad]
        _conv_rows(acts[index - 1], weight.permute(2, 1, 0), interior, bias)
        if residual is not None:
            interior += acts[residual][pad:rows - pad]
        out.relu_()
        _zero_padding(out, seg_len, pad)
        acts[index] = out
    return acts


def _drop_cheap(acts: List[Tensor], layers: Sequence[Layer]) -> List:
    """Keep the input and the outputs of wide layers; the rest cost a
    ``k``-column product to recompute, not a full GEMM."""
    return [act if index == 0 or _is_wide(layers[index - 1][0]) else None
            for index, act in enumerate(acts)]


def _chunk_backward(acts: List[Tensor], grad_out: Tensor,
                    layers: Sequence[Layer], param_grads: List[Tensor],
                    pad: int, need_input_grad: bool) -> Optional[Tensor]:
    """Accumulate one chunk's parameter gradients into ``param_grads``
    (``[dW_1, db_1, dW_2, ...]``, each ``dW`` as ``(k, C_in, C_out)``).

    Args:
        grad_out: ``(n, L)`` gradient of the band output.

    Returns:
        ``(n, L)`` gradient of the band input, or ``None``.
    """
    count, length = grad_out.shape
    seg_len = length + 2 * pad
    rows = count * seg_len
    grad = grad_out.new_zeros(count, seg_len)
    grad[:, pad:pad + length] = grad_out
    grad = grad.view(rows, 1)
    pending = {}  # activation index -> gradient reaching it via a residual
    for index in range(len(layers) - 1, -1, -1):
        weight, _, residual = layers[index]
        # ReLU backward; activations are zero on padding rows, so is grad.
        grad = torch.ops.aten.threshold_backward(grad, acts[index + 1], 0)
        if residual is not None and (residual > 0 or need_input_grad):
            skip = grad if acts[residual].shape[1] > 1 else grad.sum(
                1, keepdim=True)
            pending[residual] = pending.get(residual, 0) + skip
        param_grads[2 * index + 1] += grad.sum(0)
        _accumulate_weight_grad(acts[index], grad[pad:rows - pad],
                                param_grads[2 * index])
        if index == 0 and not need_input_grad:
            return None
        # Rows on the padding get values here, but the next ReLU backward
        # (or, for the input, the slice below) discards them.
        grad_in = grad.new_empty(rows, weight.shape[1])
        grad_in[:pad] = grad_in[rows - pad:] = 0
        _conv_rows(grad, weight.flip(2).permute(2, 0, 1),
                   grad_in[pad:rows - pad])
        if index in pending:
            grad_in += pending.pop(index)
        grad = grad_in
    return grad.view(count, seg_len)[:, pad:pad + length]


class _FusedBandNetworks(torch.autograd.Function):
    """Autograd wrapper; see :func:`fused_band_networks`."""

    @staticmethod
    def forward(ctx, coeffs: Tensor, lengths: Tuple[int, ...],
                residuals: Tuple[Optional[int], ...], pad: int,
                recompute: bool, *params: Tensor) -> Tensor:
        out = torch.empty_like(coeffs)
        saved, stores = [], None
        for band, columns, rows, layers in _chunks(coeffs, lengths,
                                                   residuals, pad, params):
            seg_len = band.length + 2 * pad
            if not recompute and rows.start == 0:
                # One buffer per kept activation and band, filled chunk by
                # chunk: no heap fragmented by thousands of kept pieces.
                band_stores = {
                    index: coeffs.new_empty(coeffs.shape[0] * seg_len,
                                            weight.shape[0])
                    for index, (weight, _, _) in enumerate(layers, 1)
                    if _is_wide(weight)}
            if not recompute:
                first, last = rows.start * seg_len, min(
                    rows.stop, coeffs.shape[0]) * seg_len
                stores = {index: store[first:last]
                          for index, store in band_stores.items()}
            acts = _chunk_forward(columns[rows], layers, pad, stores=stores)
            out[rows, band.offset] = acts[-1].view(
                -1, band.length + 2 * pad)[:, pad:pad + band.length]
            if not recompute:
                saved.append(_drop_cheap(acts, layers))
        ctx.lengths, ctx.residuals, ctx.pad = lengths, residuals, pad
        ctx.saved_acts = None if recompute else saved
        ctx.save_for_backward(coeffs, *params)
        return out

    @staticmethod
    def backward(ctx, grad_out: Tensor):
        coeffs, *params = ctx.saved_tensors
        need_input_grad = ctx.needs_input_grad[0]
        grad_coeffs = torch.zeros_like(coeffs) if need_input_grad else None
        grad_out = grad_out.contiguous()
        # Weight gradients accumulate as (k, C_in, C_out), the taps' layout.
        param_grads = [p.new_zeros(p.permute(2, 1, 0).shape) if p.dim() == 3
                       else torch.zeros_like(p) for p in params]
        per_band = 2 * len(ctx.residuals)
        saved, ctx.saved_acts = ctx.saved_acts, None
        for chunk, (band, columns, rows, layers) in enumerate(_chunks(
                coeffs, ctx.lengths, ctx.residuals, ctx.pad, params)):
            acts = _chunk_forward(columns[rows], layers, ctx.pad,
                                  saved[chunk] if saved else None)
            if saved:
                saved[chunk] = None  # free the chunk once used
            first = band.index * per_band
            grad_in = _chunk_backward(
                acts, grad_out[rows, band.offset], layers,
                param_grads[first:first + per_band], ctx.pad, need_input_grad)
            if need_input_grad:
                grad_coeffs[rows, band.offset] = grad_in
        param_grads = [g.permute(2, 1, 0) if g.dim() == 3 else g
                       for g in param_grads]
        return (grad_coeffs, None, None, None, None, *param_grads)


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
        layers = [(params[first + 2 * i], params[first + 2 * i + 1], res)
                  for i, res in enumerate(residuals)]
        band = _Band(index, slice(start, start + length), length)
        columns = coeffs[:, band.offset]
        step = max(1, ROWS_PER_CHUNK // (length + 2 * pad))
        for row in range(0, coeffs.shape[0], step):
            yield band, columns, slice(row, row + step), layers
        start += length


def fused_band_networks(coeffs: Tensor, lengths: Sequence[int],
                        weights: Sequence[Sequence[Tuple[Tensor, Tensor]]],
                        residuals: Sequence[Optional[int]],
                        recompute: bool = False) -> Tensor:
    """Run one temporal CNN per band over every pixel's coefficients.

    Args:
        coeffs: ``(N, C)`` coefficients of ``N`` pixels, the bands side by
            side (``C = sum(lengths)``), float32 or float64.
        lengths: ``L`` of each band.
        weights: per band, per layer, ``(weight (C_out, C_in, k), bias
            (C_out,))``; every layer is a 'same'-padded 1-D convolution
            followed by ReLU, the first has ``C_in = 1`` and the last
            ``C_out = 1``; the same structure for every band.
        residuals: per layer, the index of the activation added before its
            ReLU (0 is the band's input, ``i`` the output of layer ``i``;
            a 1-channel activation broadcasts), or ``None``.
        recompute: keep no activations; recompute them chunk by chunk in
            the backward pass (less memory, about a third more time).

    Returns:
        ``(N, C)``: each band's network output, in place of its input.
    """
    if len(weights) != len(lengths) or sum(lengths) != coeffs.shape[1]:
        raise ValueError(
            f'{len(weights)} band networks and bands of lengths {lengths} '
            f'do not fit coefficients shaped {tuple(coeffs.shape)}')
    kernel_size = weights[0][0][0].shape[2]
    params = [t for band in weights for layer in band for t in layer]
    return _FusedBandNetworks.apply(coeffs.contiguous(), tuple(lengths),
                                    tuple(residuals), kernel_size // 2,
                                    recompute, *params)
