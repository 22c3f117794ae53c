"""Differentiable multi-level 1-D discrete wavelet transform on torch tensors.

The transform is linear and fixed once the wavelet, the boundary mode, the
number of levels and the signal length are known, so it is built once as a
dense matrix per direction (float64, from PyWavelets' filter coefficients and
the boundary-extension rule of each mode) and applied as a single matrix
product along the transformed axis. That replaces a filter bank over many tiny
signals with one GEMM, and autograd differentiates it for free.

Conventions mirror PyWavelets:

* :func:`wavedec` returns ``[cA_n, cD_n, ..., cD_1]`` with the same lengths and
  values as ``pywt.wavedec`` for the same wavelet, mode and level, including
  levels above ``pywt.dwt_max_level`` (every coefficient then feels the
  boundary, as PyWavelets warns);
* :func:`waverec` equals ``pywt.waverec``; pass ``length`` to get exactly the
  original number of samples (``pywt.waverec`` returns one more for some odd
  lengths).
"""
from __future__ import annotations

import functools
import warnings
from typing import List, Optional, Sequence, Tuple

import numpy as np
import pywt
import torch

from ..argument_checks import (ArgumentError, check_choice, check_integer,
                               is_integer)
from ..limits import check_allocation

__all__ = ['wavedec', 'waverec']

#: Boundary modes with an exact matrix form here (``pywt.Modes`` names).
SUPPORTED_MODES = ('zero', 'constant', 'symmetric', 'reflect', 'periodic',
                   'antisymmetric', 'periodization')


def _get_wavelet(entry: str, wavelet) -> pywt.Wavelet:
    """A ``pywt.Wavelet`` for a name or wavelet object; only discrete ones."""
    if isinstance(wavelet, pywt.Wavelet):
        return wavelet
    if not isinstance(wavelet, str) or wavelet not in pywt.wavelist(
            kind='discrete'):
        raise ArgumentError(
            entry, 'wavelet', 'a discrete wavelet known to PyWavelets '
            '(pywt.wavelist(kind="discrete")) or a pywt.Wavelet', wavelet)
    return pywt.Wavelet(wavelet)


def _checked(entry: str, length: int, wavelet, level: Optional[int],
             mode: str, length_name: str = 'length'
             ) -> Tuple[pywt.Wavelet, int]:
    """The wavelet and the number of levels (``None``:
    ``pywt.dwt_max_level``) of a transform of a signal of ``length``
    samples, checked for ``entry``; the matrices are dense, so their size
    is held to the allocation limit
    (:func:`~wgse_mmseg.limits.check_allocation`)."""
    check_integer(entry, length_name, length, 1)
    check_integer(entry, 'level', level, 0, optional=True)
    check_choice(entry, 'mode', mode, SUPPORTED_MODES)
    wavelet = _get_wavelet(entry, wavelet)
    if level is None:
        level = pywt.dwt_max_level(length, wavelet.dec_len)
    # at most length + level * taps coefficients, each a row of length
    # float64 values, the matrix and the product that builds it
    rows = length + level * wavelet.dec_len
    check_allocation(2 * 8 * rows * length, f'{entry}\'s wavelet matrix',
                     f'{length_name} and level')
    return wavelet, level


def _extend(positions: np.ndarray, length: int,
            mode: str) -> Tuple[np.ndarray, np.ndarray]:
    """Map signal positions (any integers) to (source index, weight).

    A weight of 0 marks a position whose extended value is zero. Long
    extensions (filter longer than the signal) fold repeatedly, as
    PyWavelets does.
    """
    n = positions
    inside = (n >= 0) & (n < length)
    if mode == 'zero':
        return np.clip(n, 0, length - 1), inside.astype(np.float64)
    if mode == 'constant':
        return np.clip(n, 0, length - 1), np.ones(n.shape)
    if mode == 'periodic':
        return np.mod(n, length), np.ones(n.shape)
    if mode == 'symmetric':
        r = np.mod(n, 2 * length)
        return np.where(r < length, r, 2 * length - 1 - r), np.ones(n.shape)
    if mode == 'antisymmetric':
        r = np.mod(n, 2 * length)
        sign = np.where(r < length, 1.0, -1.0)
        return np.where(r < length, r, 2 * length - 1 - r), sign
    if mode == 'reflect':
        if length == 1:
            return np.zeros_like(n), np.ones(n.shape)
        period = 2 * length - 2
        r = np.mod(n, period)
        return np.where(r < length, r, period - r), np.ones(n.shape)
    raise AssertionError(mode)


def _single_level_analysis(wavelet: pywt.Wavelet, length: int,
                           mode: str) -> Tuple[np.ndarray, np.ndarray]:
    """Matrices ``(lo, hi)`` of one ``pywt.dwt`` step: ``cA = lo @ x``."""
    dec_lo = np.asarray(wavelet.dec_lo, dtype=np.float64)
    dec_hi = np.asarray(wavelet.dec_hi, dtype=np.float64)
    taps = len(dec_lo)
    j = np.arange(taps)
    if mode == 'periodization':
        # Odd signals are first made even by repeating the last sample.
        padded = length + length % 2
        n_out = padded // 2
        o = np.arange(n_out)[:, None]
        pos = np.mod(2 * o + taps // 2 - j[None, :], padded)
        src = np.minimum(pos, length - 1)
        weight = np.ones(pos.shape)
    else:
        n_out = (length + taps - 1) // 2
        o = np.arange(n_out)[:, None]
        src, weight = _extend(2 * o + 1 - j[None, :], length, mode)
    rows = np.broadcast_to(o, src.shape)
    mats = []
    for taps_values in (dec_lo, dec_hi):
        mat = np.zeros((n_out, length))
        np.add.at(mat, (rows, src), weight * taps_values[None, :])
        mats.append(mat)
    return mats[0], mats[1]


def _single_level_synthesis(wavelet: pywt.Wavelet, n_coeffs: int,
                            mode: str) -> Tuple[np.ndarray, np.ndarray]:
    """Matrices ``(lo, hi)`` of one ``pywt.idwt``:
    ``x = lo @ cA + hi @ cD``."""
    rec_lo = np.asarray(wavelet.rec_lo, dtype=np.float64)
    rec_hi = np.asarray(wavelet.rec_hi, dtype=np.float64)
    taps = len(rec_lo)
    k = np.arange(n_coeffs)[None, :]
    if mode == 'periodization':
        n_out = 2 * n_coeffs
        m = np.arange(n_out)[:, None]
        tap = np.mod(m - 2 * k + taps // 2 - 1, n_out)
    else:
        n_out = 2 * n_coeffs - taps + 2
        if n_out < 1:
            raise ValueError(
                f'{n_coeffs} coefficients are too few to invert a wavelet '
                f'with {taps} taps')
        m = np.arange(n_out)[:, None]
        tap = m + taps - 2 - 2 * k
    mats = []
    for taps_values in (rec_lo, rec_hi):
        if mode == 'periodization':
            # The periodised filter: every tap lands at its index modulo n_out.
            mat = np.zeros((n_out, n_coeffs))
            for shift in range(0, taps, n_out):
                t = tap + shift
                valid = t < taps
                np.add.at(mat, (np.broadcast_to(m, t.shape)[valid],
                                np.broadcast_to(k, t.shape)[valid]),
                          taps_values[t[valid]])
        else:
            valid = (tap >= 0) & (tap < taps)
            mat = np.where(valid, taps_values[np.clip(tap, 0, taps - 1)], 0.0)
        mats.append(mat)
    return mats[0], mats[1]


@functools.lru_cache(maxsize=256)
def _analysis(wavelet_name: str, mode: str, length: int,
              level: int) -> Tuple[np.ndarray, Tuple[int, ...]]:
    wavelet = pywt.Wavelet(wavelet_name)
    approx = np.eye(length)
    details: List[np.ndarray] = []
    for _ in range(level):
        lo, hi = _single_level_analysis(wavelet, approx.shape[0], mode)
        details.append(hi @ approx)
        approx = lo @ approx
    blocks = [approx] + details[::-1]
    matrix = np.concatenate(blocks, axis=0)
    matrix.setflags(write=False)
    return matrix, tuple(b.shape[0] for b in blocks)


@functools.lru_cache(maxsize=256)
def _synthesis(wavelet_name: str, mode: str,
               lengths: Tuple[int, ...]) -> np.ndarray:
    wavelet = pywt.Wavelet(wavelet_name)
    total = sum(lengths)
    offsets = np.cumsum((0, ) + lengths)
    selectors = [np.eye(total)[offsets[i]:offsets[i + 1]]
                 for i in range(len(lengths))]
    approx = selectors[0]
    for detail in selectors[1:]:
        if approx.shape[0] == detail.shape[0] + 1:
            approx = approx[:-1]  # pywt.waverec drops the extra sample
        if approx.shape[0] != detail.shape[0]:
            raise ValueError(
                f'coefficient lengths {list(lengths)} do not come from one '
                f'wavedec: {approx.shape[0]} approximation against '
                f'{detail.shape[0]} detail coefficients')
        lo, hi = _single_level_synthesis(wavelet, detail.shape[0], mode)
        approx = lo @ approx + hi @ detail
    approx.setflags(write=False)
    return approx


def band_lengths(length: int, wavelet, level: Optional[int] = None,
                 mode: str = 'symmetric') -> Tuple[int, ...]:
    """Coefficient counts ``(len(cA_n), len(cD_n), ..., len(cD_1))``."""
    wavelet, level = _checked('band_lengths', length, wavelet, level, mode)
    return _analysis(wavelet.name, mode, length, level)[1]


def analysis_matrix(length: int, wavelet, level: Optional[int] = None,
                    mode: str = 'symmetric') -> np.ndarray:
    """The ``(sum(band_lengths), length)`` float64 matrix of :func:`wavedec`
    (``length``: the signal's).

    Rows are ordered ``cA_n, cD_n, ..., cD_1``. Read-only and cached.
    """
    wavelet, level = _checked('analysis_matrix', length, wavelet, level,
                              mode)
    return _analysis(wavelet.name, mode, length, level)[0]


def synthesis_matrix(lengths: Sequence[int], wavelet,
                     mode: str = 'symmetric',
                     length: Optional[int] = None) -> np.ndarray:
    """The ``(n_out, sum(lengths))`` float64 matrix of :func:`waverec`.

    ``lengths`` are the band lengths in ``wavedec`` order. ``n_out`` is what
    ``pywt.waverec`` returns, or ``length`` when given (the first ``length``
    samples of it).
    """
    return _synthesis_matrix('synthesis_matrix', lengths, wavelet, mode,
                             length)


def _synthesis_matrix(entry: str, lengths: Sequence[int], wavelet,
                      mode: str, length: Optional[int]) -> np.ndarray:
    """:func:`synthesis_matrix`, its arguments checked for ``entry``."""
    check_choice(entry, 'mode', mode, SUPPORTED_MODES)
    wavelet = _get_wavelet(entry, wavelet)
    if not (isinstance(lengths, (list, tuple)) and lengths and
            all(is_integer(n, 1) for n in lengths)):
        raise ArgumentError(entry, 'the coefficient lengths',
                            'a non-empty sequence of integers >= 1',
                            lengths)
    check_allocation(2 * 8 * (2 * sum(lengths)) * sum(lengths),
                     f"{entry}'s wavelet matrix", 'the coefficient lengths')
    matrix = _synthesis(wavelet.name, mode, tuple(int(n) for n in lengths))
    if length is not None:
        check_integer(entry, 'length', length, 1, matrix.shape[0])
        matrix = matrix[:length]
    return matrix


def _check_tensor(entry: str, name: str, data, axis) -> None:
    """``data`` a tensor with an axis ``axis``."""
    if not isinstance(data, torch.Tensor):
        raise ArgumentError(entry, name, 'a torch.Tensor', data)
    if not (isinstance(axis, int) and not isinstance(axis, bool) and
            -data.dim() <= axis < data.dim()):
        raise ArgumentError(entry, 'axis', f'an axis of the {data.dim()}-D '
                            f'{name}', axis)


def _apply(matrix: np.ndarray, data: torch.Tensor, axis: int) -> torch.Tensor:
    """``matrix`` applied along ``axis`` of ``data`` (at least float32)."""
    dtype = data.dtype if data.dtype in (torch.float32,
                                         torch.float64) else torch.float32
    weight = torch.tensor(matrix, dtype=dtype, device=data.device)
    moved = data.to(dtype).movedim(axis, -1)
    return torch.matmul(moved, weight.T).movedim(-1, axis)


def wavedec(data: torch.Tensor, wavelet, mode: str = 'symmetric',
            level: Optional[int] = None, axis: int = -1) -> List[torch.Tensor]:
    """Multi-level DWT of ``data`` along ``axis``: ``pywt.wavedec``'s
    signature and defaults, on torch tensors.

    Args:
        data: a tensor of any shape; integer and half-precision inputs are
            transformed in float32, float64 stays float64.
        wavelet: a discrete PyWavelets wavelet name or ``pywt.Wavelet``.
        mode: a PyWavelets mode of zero, constant, symmetric, reflect,
            periodic, antisymmetric, periodization (PyWavelets' default,
            ``'symmetric'``; WGSE uses the paper's ``'zero'``).
        level: number of levels; ``None`` uses ``pywt.dwt_max_level``.
            A level above it warns, as PyWavelets does: every coefficient
            then feels the boundary.
        axis: the axis to transform.

    Returns:
        ``[cA_n, cD_n, ..., cD_1]``, each shaped like ``data`` except along
        ``axis``. Differentiable with respect to ``data``.
    """
    _check_tensor('wavedec', 'data', data, axis)
    wavelet, checked_level = _checked('wavedec', data.shape[axis], wavelet,
                                      level, mode, 'data.shape[axis]')
    if level is not None and level > pywt.dwt_max_level(
            data.shape[axis], wavelet.dec_len):
        warnings.warn(f'Level value of {level} is too high: all '
                      f'coefficients will experience boundary effects.',
                      stacklevel=2)
    matrix, lengths = _analysis(wavelet.name, mode, data.shape[axis],
                                checked_level)
    coeffs = _apply(matrix, data, axis)
    return list(torch.split(coeffs, list(lengths), dim=axis))


def waverec(coeffs: Sequence[torch.Tensor], wavelet,
            mode: str = 'symmetric', axis: int = -1,
            length: Optional[int] = None) -> torch.Tensor:
    """Inverse of :func:`wavedec`: ``pywt.waverec``'s signature and
    defaults, on torch tensors.

    Args:
        coeffs: ``[cA_n, cD_n, ..., cD_1]`` as returned by :func:`wavedec`.
        length: if given, return exactly this many samples (the original
            signal length); ``pywt.waverec`` may return one more.
    """
    if not (isinstance(coeffs, (list, tuple)) and coeffs):
        raise ArgumentError('waverec', 'coeffs', 'a non-empty list of '
                            'tensors [cA_n, cD_n, ..., cD_1]', coeffs)
    for index, band in enumerate(coeffs):
        _check_tensor('waverec', f'coeffs[{index}]', band, axis)
    lengths = [c.shape[axis] for c in coeffs]
    matrix = _synthesis_matrix('waverec', lengths, wavelet, mode, length)
    return _apply(matrix, torch.cat(list(coeffs), dim=axis), axis)
