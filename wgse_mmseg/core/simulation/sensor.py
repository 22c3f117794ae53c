"""The sensor's fixed per-pixel response, and the effects that shape it.

Per step, a pixel collects the charge (in its own thresholds)

    a = (gain * g_p * I + theta * d_p / f) / (theta * h_p)

with ``I`` the light intensity, ``gain`` and ``theta`` the nominal gain and
threshold, ``g_p`` and ``h_p`` the pixel's relative gain and threshold
(1 on a uniform sensor), ``d_p`` its dark firing rate in Hz at the nominal
threshold and ``f`` the readout rate. :class:`SensorMaps` holds ``g``, ``h``
and ``d``; the sensor effects below fill them. A sensor's pattern belongs
to the sensor, not the clip: each effect draws it from its ``sensor_seed``
(default 0: one sensor for every clip; ``null``: a new sensor per clip,
from the clip's seed).
"""
from typing import Optional

import torch

from ..seeding import check_seed
from .effect import (SensorEffect, SimulationContext, check_number,
                     register_effect)

__all__ = []


class SensorMaps:
    """Per-pixel relative gain, relative threshold and dark rate.

    Each is ``None`` (uniform: 1, 1, 0) or a ``(P,)`` float32 tensor. After
    the sensor effects have run, :meth:`charge` maps intensity to charge.
    """

    def __init__(self, context: SimulationContext):
        self.context = context
        self.gain: Optional[torch.Tensor] = None
        self.threshold: Optional[torch.Tensor] = None
        self.dark_rate: Optional[torch.Tensor] = None

    def normal(self, key: str, sensor_seed: Optional[int]) -> torch.Tensor:
        """``(P,)`` float32 standard normal draws of the stream ``key``."""
        return torch.randn(
            self.context.num_pixels, dtype=torch.float32,
            device=self.context.device,
            generator=self.context.generator(key, sensor_seed))

    def add_dark_rate(self, rate: torch.Tensor) -> None:
        self.dark_rate = rate if self.dark_rate is None else \
            self.dark_rate + rate

    def charge(self, intensity: torch.Tensor) -> torch.Tensor:
        """``(..., P)`` intensity to charge per step, in thresholds of each
        pixel (float32)."""
        ctx = self.context
        scale = ctx.gain / ctx.threshold
        charge = intensity * scale if self.gain is None else \
            intensity * (self.gain * scale)
        if self.dark_rate is not None:
            charge = charge + self.dark_rate / ctx.readout_hz
        if self.threshold is not None:
            charge = charge / self.threshold
        return charge


def _sensor_seed(effect, params):
    params['sensor_seed'] = check_seed(params['sensor_seed'],
                                       f'{effect}.sensor_seed', 'effects',
                                       allow_none=True)


@register_effect
class FixedPattern(SensorEffect):
    """Per-pixel gain and threshold mismatch (fixed-pattern noise).

    ``g_p = 1 + gain_std * n`` (clipped at 0) and
    ``h_p = 1 + threshold_std * n'`` (clipped at 0.05), ``n, n'`` standard
    normal per pixel. Defaults: SCSim's measured spreads (docs/simulator.md).
    """
    name = 'fixed_pattern'
    defaults = dict(gain_std=0.0577, threshold_std=0.0456, sensor_seed=0)

    def check(self, params):
        for key in ('gain_std', 'threshold_std'):
            params[key] = check_number(self.name, key, params[key], low=0)
        _sensor_seed(self.name, params)
        return params

    def apply(self, maps: SensorMaps, context: SimulationContext) -> None:
        seed = self.params['sensor_seed']
        maps.gain = (1 + self.params['gain_std'] * maps.normal(
            'fixed_pattern.gain', seed)).clamp_(min=0)
        maps.threshold = (1 + self.params['threshold_std'] * maps.normal(
            'fixed_pattern.threshold', seed)).clamp_(min=0.05)


@register_effect
class DarkCurrent(SensorEffect):
    """Dark current: charge collected without light.

    Each pixel fires ``rate * max(0, 1 + std * n)`` spikes per second in
    the dark (at the nominal threshold), ``n`` standard normal per pixel:
    ``std`` is the dark-signal non-uniformity. Defaults: SCSim's measured
    dark current (docs/simulator.md).
    """
    name = 'dark_current'
    defaults = dict(rate=93.5, std=0.39, sensor_seed=0)

    def check(self, params):
        params['rate'] = check_number(self.name, 'rate', params['rate'],
                                      low=0)
        params['std'] = check_number(self.name, 'std', params['std'], low=0)
        _sensor_seed(self.name, params)
        return params

    def apply(self, maps: SensorMaps, context: SimulationContext) -> None:
        spread = maps.normal('dark_current', self.params['sensor_seed'])
        maps.add_dark_rate(self.params['rate'] *
                           (1 + self.params['std'] * spread).clamp_(min=0))


@register_effect
class HotPixels(SensorEffect):
    """A random ``fraction`` of pixels with an extra dark rate ``rate`` Hz.

    Defaults are assumptions, not measurements (docs/simulator.md).
    """
    name = 'hot_pixels'
    defaults = dict(fraction=1e-4, rate=4000.0, sensor_seed=0)

    def check(self, params):
        params['fraction'] = check_number(self.name, 'fraction',
                                          params['fraction'], low=0, high=1)
        params['rate'] = check_number(self.name, 'rate', params['rate'],
                                      low=0)
        _sensor_seed(self.name, params)
        return params

    def apply(self, maps: SensorMaps, context: SimulationContext) -> None:
        draw = torch.rand(
            context.num_pixels, device=context.device,
            generator=context.generator('hot_pixels',
                                        self.params['sensor_seed']))
        maps.add_dark_rate((draw < self.params['fraction']).to(
            torch.float32) * self.params['rate'])
