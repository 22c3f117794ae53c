"""Classical spike-stream representations, as enhancers like WGSE.

Each maps a spike stream ``(B, T, H, W)`` to a representation
``(B, T, H, W)`` with the same ``T``, so that the backbone's
``in_channels=T`` does not change, and is selected in a config exactly like
WGSE::

    model = dict(data_preprocessor=dict(enhancer=dict(type='TFI')))

They have no parameters and need only torch; MMSeg's registry knows them by
their class names (:mod:`wgse_mmseg.models.enhancers`). Each is computed with a
handful of vectorised tensor operations (cumulative sums and maxima, average
pooling), in float32 (float64 for float64 input) even under autocast, like
WGSE's transform.

Where they come from:

* :class:`TFP` (texture from playback) and :class:`TFI` (texture from
  inter-spike intervals): Zhu, Duan, Xiong, Xiao, Xiong, Huang, "A
  retina-inspired sampling method for visual texture reconstruction",
  ICME 2019. TFP estimates the light intensity as the spike count in a
  window divided by its length; TFI as the inverse of the interval between
  the spikes around each instant.
* :class:`SpatialMeanFilter` and :class:`TemporalMeanFilter`: the
  mean-filter baselines of the denoising comparison in the WGSE paper
  (Zhang, Jia, Yu, Huang, "Learning temporal-ordered representation for
  spike streams based on discrete wavelet transforms", AAAI 2023): a
  ``k x k`` box filter on each frame, and a ``k``-step box filter along
  time at each pixel.

A temporal mean filter over ``k`` steps and TFP with a window of ``k`` are
the same operator; :class:`TFP` is :class:`TemporalMeanFilter` with the
window of an intensity estimate (long) as its default rather than that of a
denoiser (short), and both names are registered because the literature and
the experiment grids use both.
"""
import torch
import torch.nn.functional as F
from torch import nn

from ..argument_checks import check_integer
from .checks import check_finite

__all__ = ['TemporalMeanFilter', 'TFP', 'TFI', 'SpatialMeanFilter']


class _FixedRepresentation(nn.Module):
    """A parameter-free map ``(B, T, H, W) -> (B, T, H, W)``.

    Subclasses implement :meth:`represent` on a float32 (float64 for float64
    input) stream; :meth:`forward` checks the shape and disables autocast.
    """

    def represent(self, spikes: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def forward(self, spikes: torch.Tensor) -> torch.Tensor:
        """``spikes`` ``(B, T, H, W)`` -> float ``(B, T, H, W)``; NaN or Inf
        in ``spikes`` raises ``ValueError``, as in WGSE."""
        name = type(self).__name__
        if spikes.dim() != 4 or spikes.shape[1] < 1:
            raise ValueError(f'{name} expects spikes shaped (B, T, H, W) with '
                             f'T >= 1, got {tuple(spikes.shape)}')
        check_finite(name, 'spikes', spikes)
        dtype = torch.float64 if spikes.dtype == torch.float64 else \
            torch.float32
        with torch.autocast(spikes.device.type, enabled=False):
            return self.represent(spikes.to(dtype))


class TemporalMeanFilter(_FixedRepresentation):
    """Mean over the ``kernel_size`` steps centred on each step, per pixel.

    At the ends of the stream the window is cut to the steps inside it and
    the mean is taken over those (no zero padding, so the ends are not
    darkened). Computed from one cumulative sum along time, so the cost does
    not depend on ``kernel_size``.

    Args:
        kernel_size: odd window length in steps; may exceed ``T`` (every
            window is then cut to the whole stream near its centre).
    """

    def __init__(self, kernel_size: int = 3):
        super().__init__()
        self.kernel_size = check_integer(type(self).__name__,
                                         self._size_name, kernel_size, 1,
                                         odd=True)

    #: what the constructor calls the window's length
    _size_name = 'kernel_size'

    def represent(self, spikes: torch.Tensor) -> torch.Tensor:
        num_steps = spikes.shape[1]
        # a window beyond the stream's ends is cut to it
        half = min(self.kernel_size // 2, num_steps)
        # totals[:, i] = sum of spikes[:, :i]
        totals = F.pad(spikes.cumsum(dim=1), (0, 0, 0, 0, 1, 0))
        steps = torch.arange(num_steps, device=spikes.device)
        upper = (steps + half + 1).clamp(max=num_steps)
        lower = (steps - half).clamp(min=0)
        lengths = (upper - lower).to(spikes.dtype).view(1, num_steps, 1, 1)
        return (totals.index_select(1, upper) -
                totals.index_select(1, lower)) / lengths


class TFP(TemporalMeanFilter):
    """Texture from playback: the spike rate in a window around each step.

    ``TFP(window=w)`` is ``TemporalMeanFilter(kernel_size=w)`` (see the
    module docstring): per pixel and step, the number of spikes in the ``w``
    steps centred on it divided by the number of those steps inside the
    stream, a value in ``[0, 1]`` proportional to the light intensity.

    Args:
        window: odd window length in steps (Zhu et al. use windows of tens
            of steps).
    """

    _size_name = 'window'

    def __init__(self, window: int = 33):
        super().__init__(kernel_size=window)


class SpatialMeanFilter(_FixedRepresentation):
    """Mean over the ``kernel_size x kernel_size`` pixels centred on each
    pixel, per frame.

    At the image borders the mean is over the pixels inside the image.

    Args:
        kernel_size: odd side of the square window.
    """

    def __init__(self, kernel_size: int = 3):
        super().__init__()
        self.kernel_size = check_integer('SpatialMeanFilter', 'kernel_size',
                                         kernel_size, 1, odd=True)

    def represent(self, spikes: torch.Tensor) -> torch.Tensor:
        # a window wider than the image is cut to it: from any pixel,
        # 2 * max(H, W) - 1 covers the whole image
        size = min(self.kernel_size, 2 * max(spikes.shape[-2:]) - 1)
        return F.avg_pool2d(spikes, size, stride=1, padding=size // 2,
                            count_include_pad=False)


class TFI(_FixedRepresentation):
    """Texture from inter-spike intervals: ``1 / ISI`` at each step.

    Per pixel, the interval around step ``t`` runs from the last spike at
    or before ``t`` to the first spike after ``t``; the output is its
    inverse, a rate in ``(0, 1]`` per step (a pixel firing every ``P`` steps
    gives ``1 / P``). Where the stream's start or end cuts the interval, the
    nearest complete interval stands in for it: before the first spike, the
    first interval; from the last spike on, the last one (so a periodic
    stream gives its rate at every step). A pixel with fewer than two spikes
    has no interval; its value is its spike count divided by ``T`` (``0``
    for no spike, ``1 / T`` for one), always finite.

    Input must be binary (0/1): intervals between events are meaningless
    for anything else, and a stream with other values raises ``ValueError``.
    The output does not depend differentiably on the input (no gradient
    flows to the spikes, which are data).
    """

    def represent(self, spikes: torch.Tensor) -> torch.Tensor:
        fired = spikes == 1
        if not (fired | (spikes == 0)).all():
            bad = spikes[~(fired | (spikes == 0))][0].item()
            raise ValueError(f'TFI expects binary spikes (0 or 1), found the '
                             f'value {bad}; intervals between spikes are '
                             f'undefined for other values')
        num_steps = spikes.shape[1]
        # pixel-major (B, H, W, T): the scans below run along contiguous
        # memory, several times faster than along dim 1
        fired = fired.permute(0, 2, 3, 1).contiguous()
        steps = torch.arange(num_steps, device=spikes.device,
                             dtype=torch.int32)
        # last spike at or before t (-1: none); first spike at or after t (T)
        last = torch.where(fired, steps, -1).cummax(dim=-1).values
        upcoming = torch.where(fired, steps, num_steps).flip(-1).cummin(
            dim=-1).values.flip(-1)
        # first spike after t; last spike before t
        after = torch.cat(
            [upcoming[..., 1:], torch.full_like(last[..., :1], num_steps)],
            dim=-1)
        before = torch.cat(
            [torch.full_like(last[..., :1], -1), last[..., :-1]], dim=-1)
        first, final = upcoming[..., :1], last[..., -1:]
        first_interval = after.gather(-1, first.clamp(max=num_steps - 1)) - \
            first
        last_interval = final - before.gather(-1, final.clamp(min=0))
        interval = torch.where(last < 0, first_interval, after - last)
        interval = torch.where(after >= num_steps, last_interval, interval)
        rate = 1.0 / interval.clamp(min=1).to(spikes.dtype)
        count = fired.sum(dim=-1, keepdim=True, dtype=spikes.dtype)
        rate = torch.where(count >= 2, rate, count / num_steps)
        return rate.permute(0, 3, 1, 2).contiguous()
