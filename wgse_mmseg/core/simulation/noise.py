"""Random changes of the charge collected in each readout step.

Applied after the sensor's fixed response, in this order whatever the
scene's order: ``jitter`` (when each step's integration window starts and
ends), then ``shot_noise`` (the photon and dark-electron counts in that
window).
"""
import torch

from .effect import ChargeEffect, check_number, register_effect

__all__ = []


@register_effect
class ReadoutJitter(ChargeEffect):
    """Readout timing jitter.

    Readout ``t`` happens at ``t + e_t`` readout periods, ``e_t`` normal with
    standard deviation ``std`` (clipped to half a period), independent per
    pixel and readout. Step ``t`` then integrates for ``1 + e_t - e_(t-1)``
    periods: charge moves between neighbouring steps, none is created or
    lost over the clip beyond the two end windows. Default: 100 ns at 40 kHz
    (an assumption, docs/simulator.md).
    """
    name = 'jitter'
    order = 10
    defaults = dict(std=0.004)

    def check(self, params):
        params['std'] = check_number(self.name, 'std', params['std'], low=0,
                                     high=0.5)
        return params

    def start(self, maps, context) -> None:
        self._generator = context.generator('jitter')
        self._previous = self._offsets(1, context.num_pixels,
                                       context.device)[0]

    def _offsets(self, steps, pixels, device) -> torch.Tensor:
        offsets = torch.randn((steps, pixels), device=device,
                              generator=self._generator)
        return offsets.mul_(self.params['std']).clamp_(-0.5, 0.5)

    def __call__(self, charge: torch.Tensor) -> torch.Tensor:
        offsets = self._offsets(charge.shape[0], charge.shape[1],
                                charge.device)
        previous = torch.cat([self._previous[None], offsets[:-1]])
        self._previous = offsets[-1]
        return charge * (1 + offsets - previous)


@register_effect
class ShotNoise(ChargeEffect):
    """Photon shot noise: the electrons collected per step are Poisson.

    A pixel's threshold is ``electrons`` electrons (times its relative
    threshold under ``fixed_pattern``); a step expecting ``lam`` electrons
    collects ``Poisson(lam)``, light and dark current alike. Counts are
    drawn exactly below ``exact_below`` expected electrons and from the
    normal approximation ``lam + sqrt(lam) n`` above, where the two agree
    to far better than the fixed point resolves. Default ``electrons``:
    SCSim's photon count for white (docs/simulator.md).
    """
    name = 'shot_noise'
    order = 20
    defaults = dict(electrons=5.0e4, exact_below=1000.0)

    def check(self, params):
        params['electrons'] = check_number(self.name, 'electrons',
                                           params['electrons'], low=0,
                                           low_open=True)
        params['exact_below'] = check_number(self.name, 'exact_below',
                                             params['exact_below'], low=0)
        return params

    def start(self, maps, context) -> None:
        self._generator = context.generator('shot_noise')
        electrons = torch.tensor(self.params['electrons'],
                                 dtype=torch.float32, device=context.device)
        self._electrons = electrons if maps.threshold is None else \
            electrons * maps.threshold

    def __call__(self, charge: torch.Tensor) -> torch.Tensor:
        expected = charge * self._electrons
        counts = torch.randn(expected.shape, device=expected.device,
                             generator=self._generator)
        counts.mul_(expected.sqrt()).add_(expected).clamp_(min=0)
        small = expected < self.params['exact_below']
        if small.any():
            counts[small] = torch.poisson(expected[small],
                                          generator=self._generator)
        return counts / self._electrons
