"""Integrate-and-fire in fixed point: exact, and the same on every device.

The model (Eq. 1 of the paper): a pixel's charge ``A(t) = int alpha I dt mod
theta`` fires a spike at each multiple of the threshold; the camera reads a
one-bit flag per pixel each readout step (25 us at 40 kHz). Here charge is
counted in thresholds of the pixel, so the per-step charge is
``a_t = alpha I_t / theta``, and with the charge ``x_t = q_0 + sum a_s``
(subtract reset: no charge is lost) the pixel reads a spike at step ``t``
when ``floor(x_t) > floor(x_(t-1))``. A pixel reads at most one spike per
step: crossings beyond the first in one readout period are not counted (the
one-bit readout), so the rate saturates at one spike per step. Below
saturation (``a_t < 1``, which always holds with ``gain <= threshold`` and
no effects) the count over ``T`` steps is exactly
``floor(q_0 + sum_t a_t)``.

Charge is an int32 count of ``2**-24`` thresholds (:data:`ONE` is one
threshold), so the integration itself is exact integer arithmetic: sums are
associative, and CPU and GPU give the same spikes bit for bit. The
fractional charge ``frac(x)`` carries from block to block; the count
``floor(x)`` within a block is bits 24-31 of ``x``. A step's charge is
resolved to ``2**-24`` thresholds (``6e-8``: a rate of 0.0024 Hz at 40 kHz);
charge beyond :data:`_MAX_STEP_CHARGE` thresholds per step is clipped (such a
pixel fires every step anyway).

Steps are integrated in blocks short enough that ``x`` stays below
``2**31`` (:data:`MAX_BLOCK_STEPS`, or :data:`MAX_LINEAR_BLOCK_STEPS` for a
closed-form block) and, on CPU, in tiles of pixels, which run side by side
on torch's threads, one thread each.

Two backends integrate, chosen by ``backend`` (:data:`CHOICES`), as WGSE's
band networks are:

* ``'torch'``: torch operations, on any device: per tile, the running sums,
  the counts, their narrowing and difference (four passes);
* ``'compiled'``: on the CPU, a compiled kernel (``_integrate_and_fire.c``,
  built by ``setup.py``) integrates a tile in one pass: step by step it adds
  the step's charge, reads the spike and keeps the fraction, which gives
  the same spikes and carried charge bit for bit.

``'auto'`` runs the compiled kernel on the CPU where it was built
(:func:`compiled_unavailable`) and the torch path elsewhere (no C
compiler, the GPU); naming a backend that cannot run is an error.
"""
from typing import Callable, Iterator, List, NamedTuple, Optional, Tuple

import numpy as np
import torch

from ..parallel import for_each_on_threads

try:
    from . import _integrate_and_fire
except ImportError:  # installed without a C compiler: the torch path runs
    _integrate_and_fire = None

__all__ = []

#: the backends that integrate (see the module docstring)
BACKENDS = ('torch', 'compiled')
#: what ``backend`` accepts
CHOICES = ('auto', ) + BACKENDS

_FRACTION_BITS = 24
ONE = 1 << _FRACTION_BITS
_MAX_STEP_CHARGE = 64
MAX_BLOCK_STEPS = 32  # steps of up to 2 thresholds each: x < 2**31
MAX_LINEAR_BLOCK_STEPS = 120  # steps below 1 threshold each: x < 2**31
_CPU_TILE = 1 << 14  # pixels per tile: larger ops beat cache-sized ones


def compiled_unavailable() -> Optional[str]:
    """Why this installation cannot run the compiled kernel at all, or
    ``None``."""
    if _integrate_and_fire is None:
        return ('the compiled extension was not built (installed without a '
                'C compiler)')
    return None


def resolve_backend(backend: str, device) -> str:
    """The backend (``'torch'`` or ``'compiled'``) that integrates on
    ``device`` for the configured ``backend`` (one of :data:`CHOICES`).

    Raises:
        ValueError: an unknown name, or ``'compiled'`` where it cannot run
            (not built, or not on the CPU), with the reason and the
            choices.
    """
    device = torch.device(device)
    reason = compiled_unavailable() or (
        None if device.type == 'cpu' else
        f'it runs on the CPU, not on {device}')
    if backend == 'auto':
        return 'torch' if reason else 'compiled'
    choices = ', '.join(map(repr, CHOICES)) + (
        f' (unavailable here: {compiled_unavailable()})'
        if compiled_unavailable() else '')
    if backend not in BACKENDS:
        raise ValueError(f'backend must be one of {choices}; got '
                         f'{backend!r}')
    if backend == 'compiled' and reason:
        raise ValueError(f"backend='compiled' cannot integrate: {reason}. "
                         f'Choices: {choices}')
    return backend


def initial_charge(num_pixels: int, seed: int) -> torch.Tensor:
    """``(P,)`` int32 initial charge, uniform over ``[0, 1)`` threshold in
    units of ``2**-24`` (``q_0 = initial_charge / ONE``).

    Drawn on the CPU from ``seed`` alone, so every device starts from the
    same charge.
    """
    generator = torch.Generator().manual_seed(seed)
    return torch.randint(0, ONE, (num_pixels, ), generator=generator,
                         dtype=torch.int32)


def quantise(charge: torch.Tensor) -> Tuple[torch.Tensor, bool]:
    """Float charge per step, in thresholds, to fixed point.

    Args:
        charge: ``(K, P)`` float charge per step, ``>= 0``.

    Returns:
        ``(steps, saturated)``: ``(K, P)`` int32 charge in units of
        ``2**-24`` thresholds (rounded down), and whether any step collects
        a whole threshold or more. Such a step fires whatever the pixel's
        charge, so only its fraction matters for later steps: it is kept as
        ``1 + frac(a)``, which leaves the spikes and the carried charge as
        they are and keeps every step below two thresholds. Inf saturates
        as any charge beyond a threshold does; NaN (a float32 overflow in
        the effects' products, such as Inf - Inf) is a ``ValueError``
        rather than a spike of every step.
    """
    if bool(torch.isnan(charge).any()):
        raise ValueError(
            f'simulate_spikes: {int(torch.isnan(charge).sum())} charge '
            f'value(s) of a step are NaN: the product of the gain, the '
            f'threshold and the effects\' parameters overflows float32 '
            f'({torch.finfo(torch.float32).max:.4g}); lower the largest '
            f'of them')
    charge = charge.clamp(0, _MAX_STEP_CHARGE)
    saturated = bool(charge.max() >= 1)
    if saturated:
        charge = torch.where(charge >= 1, charge.frac() + 1, charge)
    return (charge * ONE).to(torch.int32), saturated


def _chunks(steps: int, size: int) -> Iterator[Tuple[int, int]]:
    """``[0, steps)`` in consecutive ranges of at most ``size``."""
    for start in range(0, steps, size):
        yield start, min(start + size, steps)


class _LinearCharge(NamedTuple):
    """Charge per step linear in a weight ``w``: ``base + w * slope``.

    ``base``: ``(P,)`` int32 fixed point; ``slope``: ``(P,)`` int32 per
    unit of weight, or ``None`` for a constant charge.
    """
    base: torch.Tensor
    slope: Optional[torch.Tensor]


class _TileBuffers(NamedTuple):
    """One thread's working space for a tile: running charge and counts."""
    sums: torch.Tensor  # (K + 1, tile) int32
    counts: torch.Tensor  # (K + 1, tile) uint8

    @classmethod
    def empty(cls, block_steps: int, tile: int,
              device: torch.device) -> '_TileBuffers':
        shape = (block_steps + 1, tile)
        return cls(torch.empty(shape, dtype=torch.int32, device=device),
                   torch.empty(shape, dtype=torch.uint8, device=device))


class Integrator:
    """Integrate-and-fire of ``P`` pixels, block of steps after block.

    Args:
        num_pixels: ``P``.
        seed: seeds the initial charge (:func:`initial_charge`).
        device: where the charge lives and the arithmetic runs.
        block_steps: steps its buffers hold; longer blocks (and blocks
            longer than the overflow bounds) are integrated in parts.
        backend: one of :data:`CHOICES` (:func:`resolve_backend`).

    Each call takes the charge of the next ``K`` steps and writes their
    ``(K, P)`` uint8 0/1 spikes into ``out``; both backends give the same
    spikes and carried charge bit for bit.
    """

    def __init__(self, num_pixels: int, seed: int, device,
                 block_steps: int = MAX_BLOCK_STEPS, backend: str = 'auto'):
        device = torch.device(device)
        #: the backend that integrates: ``'torch'`` or ``'compiled'``
        self.backend = resolve_backend(backend, device)
        self.charge = initial_charge(num_pixels, seed).to(device)
        self.tile = num_pixels if device.type == 'cuda' else min(
            num_pixels, _CPU_TILE)
        self.block_steps = block_steps
        self._index = torch.arange(block_steps + 1, dtype=torch.int32,
                                   device=device).view(-1, 1)
        self._buffers: List[_TileBuffers] = []

    def _for_each_tile(self, task: Callable[[int, int, '_TileBuffers'],
                                            None]) -> None:
        """``task(begin, end, buffers)`` for every tile of pixels; on the
        CPU the tiles run side by side on torch's threads
        (:func:`~wgse_mmseg.core.parallel.for_each_on_threads`), each thread
        with its own buffers, kept for the next call (``None`` for the compiled
        kernel, which needs none)."""
        pixels = self.charge.numel()
        spare = iter(self._buffers)

        def make_buffers() -> Optional[_TileBuffers]:
            if self.backend == 'compiled':
                return None
            buffers = next(spare, None)
            if buffers is None:
                buffers = _TileBuffers.empty(self.block_steps, self.tile,
                                             self.charge.device)
                self._buffers.append(buffers)
            return buffers

        def tile(index: int, buffers: _TileBuffers) -> None:
            begin = index * self.tile
            task(begin, min(begin + self.tile, pixels), buffers)

        for_each_on_threads(tile, -(-pixels // self.tile), make_buffers)

    @staticmethod
    def linear_charge(first: torch.Tensor, last: Optional[torch.Tensor],
                      denominator: int) -> Optional[_LinearCharge]:
        """Fixed-point charge going linearly from ``first`` (weight 0) to
        ``last`` (weight ``denominator``; ``None``: constant), or ``None``
        unless it stays below one threshold (then use :func:`quantise` and
        :meth:`per_step`).

        The slope is rounded toward zero, so every step's charge lies
        between ``first`` and ``last``, within ``denominator * 2**-24``
        thresholds of the exact interpolation.

        Args:
            first, last: ``(P,)`` float charge per step, in thresholds.
            denominator: positive integer.
        """
        top = first.max() if last is None else torch.maximum(
            first.max(), last.max())
        if not bool(top < 1):
            return None
        base = (first * ONE).to(torch.int32)
        if last is None:
            return _LinearCharge(base, None)
        difference = (last * ONE).to(torch.int32) - base
        return _LinearCharge(
            base, torch.div(difference, denominator, rounding_mode='trunc'))

    def linear(self, charge: _LinearCharge, weights: np.ndarray,
               out: torch.Tensor) -> None:
        """Steps whose charge is ``base + weights[k] * slope``.

        The running sums are closed forms,
        ``x_k = x_0 + k * base + W_k * slope`` with ``W_k`` the sum of the
        first ``k`` weights: no per-step charge is materialised.

        Args:
            charge: from :meth:`linear_charge`.
            weights: ``(K,)`` non-negative integers.
            out: ``(K, P)`` uint8 spikes.
        """
        size = min(self.block_steps, MAX_LINEAR_BLOCK_STEPS)
        for start, stop in _chunks(len(weights), size):
            self._linear(charge, weights[start:stop], out[start:stop])

    def _linear(self, charge: _LinearCharge, weights: np.ndarray,
                out: torch.Tensor) -> None:
        if self.backend == 'compiled':
            self._linear_compiled(charge, weights, out)
            return
        steps = len(weights)
        base, slope = charge
        cumulative = None
        if slope is not None and weights.any():
            cumulative = torch.from_numpy(
                np.concatenate([[0], np.cumsum(weights)])).to(
                    device=base.device, dtype=torch.int32).view(-1, 1)

        def tile(begin: int, end: int, buffers: _TileBuffers) -> None:
            sums = buffers.sums[:steps + 1, :end - begin]
            torch.addcmul(self.charge[begin:end], self._index[:steps + 1],
                          base[begin:end], out=sums)
            if cumulative is not None:
                sums.addcmul_(cumulative, slope[begin:end])
            self._fire(sums, begin, end, out, buffers, saturated=False)

        self._for_each_tile(tile)

    def _linear_compiled(self, charge: _LinearCharge, weights: np.ndarray,
                         out: torch.Tensor) -> None:
        """:meth:`_linear` with the compiled kernel: each step adds
        ``base + weights[k] * slope`` (at most ``|last - first|``)."""
        base, slope = (None if t is None else t.contiguous()
                       for t in charge)
        weights = torch.from_numpy(np.ascontiguousarray(weights, np.int32))
        _check_spike_rows(out, len(weights), self.charge.numel())

        def tile(begin: int, end: int, _) -> None:
            _integrate_and_fire.fire_linear(
                _address(self.charge, begin), _address(base, begin),
                0 if slope is None else _address(slope, begin),
                weights.data_ptr(), len(weights), end - begin,
                _address(out, begin), out.stride(0))

        self._for_each_tile(tile)

    def per_step(self, charge: torch.Tensor, saturated: bool,
                 out: torch.Tensor) -> None:
        """Steps with any charge each.

        Args:
            charge: ``(K, P)`` int32 fixed-point charge per step, from
                :func:`quantise`.
            saturated: :func:`quantise`'s flag.
            out: ``(K, P)`` uint8 spikes.
        """
        size = min(self.block_steps, MAX_BLOCK_STEPS)
        for start, stop in _chunks(charge.shape[0], size):
            self._per_step(charge[start:stop], saturated, out[start:stop])

    def _per_step(self, charge: torch.Tensor, saturated: bool,
                  out: torch.Tensor) -> None:
        steps = charge.shape[0]
        if self.backend == 'compiled':
            # saturation needs nothing: one spike at most
            charge = charge.to(torch.int32).contiguous()
            _check_spike_rows(out, steps, self.charge.numel())
            self._for_each_tile(
                lambda begin, end, _: _integrate_and_fire.fire_per_step(
                    _address(self.charge, begin), _address(charge, begin),
                    charge.stride(0), steps, end - begin,
                    _address(out, begin), out.stride(0)))
            return

        def tile(begin: int, end: int, buffers: _TileBuffers) -> None:
            sums = buffers.sums[:steps + 1, :end - begin]
            sums[0] = self.charge[begin:end]
            for step in range(steps):
                torch.add(sums[step], charge[step, begin:end],
                          out=sums[step + 1])
            self._fire(sums, begin, end, out, buffers, saturated)

        self._for_each_tile(tile)

    def _fire(self, sums: torch.Tensor, begin: int, end: int,
              out: torch.Tensor, buffers: '_TileBuffers',
              saturated: bool) -> None:
        """Spikes of pixels ``begin:end`` from their ``(K + 1, tile)``
        running charge; keep the final fraction as the pixels' charge."""
        steps = sums.shape[0] - 1
        torch.bitwise_and(sums[steps], ONE - 1, out=self.charge[begin:end])
        sums.bitwise_right_shift_(_FRACTION_BITS)  # thresholds crossed
        counts = buffers.counts[:steps + 1, :end - begin]
        counts.copy_(sums)
        spikes = out[:, begin:end]
        torch.sub(counts[1:], counts[:-1], out=spikes)
        if saturated:  # a step of 1 + frac(a) may cross twice
            spikes.clamp_(max=1)


def _address(tensor: torch.Tensor, element: int) -> int:
    """Address of element ``element`` of a ``(P,)`` tensor or of column
    ``element`` of a ``(K, P)`` tensor's first row."""
    return tensor.data_ptr() + element * tensor.element_size()


def _check_spike_rows(out: torch.Tensor, steps: int, pixels: int) -> None:
    """What the compiled kernel assumes of ``out``: a ``(steps, pixels)``
    uint8 CPU tensor with contiguous rows."""
    if (out.dtype != torch.uint8 or out.device.type != 'cpu'
            or tuple(out.shape) != (steps, pixels)
            or (pixels > 1 and out.stride(1) != 1)):
        raise ValueError(
            f'spikes must be a ({steps}, {pixels}) uint8 CPU tensor with '
            f'contiguous rows, got {tuple(out.shape)} {out.dtype} on '
            f'{out.device} with strides {out.stride()}')
