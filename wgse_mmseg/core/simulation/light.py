"""Light per readout step, and the base model's resampling of frames.

A :class:`Light` produces the intensity of each readout step lazily, a
block of steps at a time, so a 512x1024 clip of 129 steps never holds all
its float frames at once. The base model's light is :class:`LinearLight`:
``N`` frames spread evenly over the ``T`` steps (frame ``n`` at step
``n (T - 1) / (N - 1)``, so an odd ``N`` puts its middle frame on the middle
step), linearly interpolated between them; one frame is a still scene.
Light effects (:mod:`.interpolation`, :mod:`.camera_motion`) supply other
lights.
"""
from typing import Iterator, Tuple

import numpy as np
import torch

__all__ = []


def _balanced(start: int, stop: int,
              max_steps: int) -> Iterator[Tuple[int, int]]:
    """``[start, stop)`` in as few ranges of at most ``max_steps`` as can
    be, of near-equal length (129 steps by 64: 43, 43, 43)."""
    count = -(-(stop - start) // max_steps)
    bounds = [start + (stop - start) * i // count for i in range(count + 1)]
    yield from zip(bounds[:-1], bounds[1:])


class Light:
    """Intensity in [0, 1] of each of ``num_steps`` readout steps.

    Attributes:
        resampling: how frames became per-step light (the metadata's
            ``resampling``).
        linear: whether each block is linear in time between two frames
            (then :class:`LinearLight`'s segment methods apply and the
            integrator needs no per-step intensity).
    """
    resampling = ''
    linear = False

    def __init__(self, num_steps: int):
        self.num_steps = num_steps

    def blocks(self, max_steps: int) -> Iterator[Tuple[int, int]]:
        """Consecutive ``(start, stop)`` step ranges covering all steps,
        each at most ``max_steps`` long."""
        return _balanced(0, self.num_steps, max_steps)

    def intensity(self, start: int, stop: int) -> torch.Tensor:
        """``(stop - start, P)`` float32 intensity of those steps (may be
        a broadcast view: read it, do not write it)."""
        raise NotImplementedError


class LinearLight(Light):
    """Frames spread evenly over the steps, linearly interpolated.

    Step ``t`` lies in segment ``k_t`` (between frames ``k_t`` and
    ``k_t + 1``) at the integer weight ``m_t`` out of ``q = T - 1``: exact
    rational positions, which the integrator's closed form uses as they
    are.

    Args:
        intensity: ``(N, H, W)`` float32 in [0, 1].
        num_steps: ``T``.
    """
    linear = True

    def __init__(self, intensity: torch.Tensor, num_steps: int):
        super().__init__(num_steps)
        self.frames = intensity.reshape(intensity.shape[0], -1)
        count = self.frames.shape[0]
        self.resampling = 'static' if count == 1 else 'linear'
        self.denominator = max(num_steps - 1, 1)
        numerator = np.arange(num_steps) * (count - 1)
        self._segment = np.minimum(numerator // self.denominator,
                                   max(count - 2, 0))
        self._weight = numerator - self._segment * self.denominator

    def blocks(self, max_steps: int) -> Iterator[Tuple[int, int]]:
        """As :meth:`Light.blocks`, each block within one segment."""
        changes = np.flatnonzero(np.diff(self._segment)) + 1
        bounds = [0, *changes.tolist(), self.num_steps]
        for start, stop in zip(bounds[:-1], bounds[1:]):
            yield from _balanced(start, stop, max_steps)

    def segment(self, start: int) -> int:
        """The segment of step ``start`` (and of its block)."""
        return int(self._segment[start])

    def segment_frames(self, index: int) -> Tuple[torch.Tensor,
                                                  torch.Tensor]:
        """The ``(P,)`` frames segment ``index`` lies between (the same
        tensor twice for a single frame)."""
        first = self.frames[index]
        if index + 1 == self.frames.shape[0]:
            return first, first
        return first, self.frames[index + 1]

    def weights(self, start: int, stop: int) -> np.ndarray:
        """``(K,)`` integer weights of steps ``start .. stop - 1`` in
        ``[0, denominator]``."""
        return self._weight[start:stop]

    def fractions(self, start: int, stop: int) -> torch.Tensor:
        """``(K, 1)`` float32 ``weights / denominator`` on the frames'
        device: each step's position between its two frames."""
        return torch.from_numpy(self.weights(start, stop) /
                                self.denominator).to(
                                    device=self.frames.device,
                                    dtype=torch.float32).view(-1, 1)

    def intensity(self, start: int, stop: int) -> torch.Tensor:
        first, last = self.segment_frames(self.segment(start))
        if last is first:
            return first.expand(stop - start, -1)
        return torch.lerp(first, last, self.fractions(start, stop))
