"""The ``camera_motion`` effect: a still image seen by a moving camera.

The image is warped along a trajectory centred on the middle step, where it
is seen as it is (so its label holds there, as for video, whose middle
frame sits on the middle step). At time ``tau`` from the middle, content at
``q`` (pixels from the image centre, ``y`` down) appears at

    p = s(tau) R(phi(tau)) q + tau * translation,
    s(tau) = 1 + tau * zoom,   phi(tau) = tau * rotation,

``R(phi)`` turning content counter-clockwise on screen. ``tau`` is in
seconds (``per='second'``: ``translation`` in px/s, ``rotation`` in deg/s,
``zoom`` in 1/s) or in clip lengths (``per='clip'``: the totals from the
first step to the last). Outside the image the border is repeated.
"""
import math
from typing import Iterator, Tuple

import torch

from .effect import (LightEffect, check_choice, check_number, check_pair,
                     register_effect)
from .light import Light
from .warp import affine_grid, pixel_scale, sample, warp_block_steps

__all__ = ['CameraMotion', 'CameraMotionLight']


class CameraMotionLight(Light):
    """A still image warped along a camera trajectory, per step.

    Args:
        image: ``(H, W)`` float32 in [0, 1].
        num_steps: ``T``.
        times: ``(T,)`` float64 ``tau`` of each step (0 at the middle).
        translation: ``(dx, dy)`` per unit of ``tau``, pixels.
        rotation: degrees per unit of ``tau``.
        zoom: relative scale change per unit of ``tau``.
    """
    resampling = 'camera_motion'

    def __init__(self, image: torch.Tensor, num_steps: int,
                 times: torch.Tensor, translation, rotation: float,
                 zoom: float):
        super().__init__(num_steps)
        self.image = image
        self.times = times
        self.translation = translation
        self.rotation = math.radians(rotation)
        self.zoom = zoom

    def blocks(self, max_steps: int) -> Iterator[Tuple[int, int]]:
        return super().blocks(
            warp_block_steps(max_steps, *self.image.shape))

    def source_maps(self, start: int, stop: int) -> torch.Tensor:
        """``(K, 2, 3)`` float64 affine maps, in pixels: step ``k`` shows
        at pixel ``p`` the image at ``M p + b`` (``[M | b]``)."""
        height, width = self.image.shape
        centre = torch.tensor([(width - 1) / 2, (height - 1) / 2],
                              dtype=torch.float64)
        tau = self.times[start:stop]
        angle, scale = tau * self.rotation, 1 + tau * self.zoom
        cos, sin = torch.cos(angle) / scale, torch.sin(angle) / scale
        # M = R(-phi) / s, with R(phi) turning content counter-clockwise on
        # screen (y down): R(-phi) = [[cos, -sin], [sin, cos]]
        matrix = torch.stack([torch.stack([cos, -sin], -1),
                              torch.stack([sin, cos], -1)], -2)
        shift = tau[:, None] * torch.tensor(self.translation,
                                            dtype=torch.float64)
        offset = centre - (matrix @ (centre + shift)[..., None])[..., 0]
        return torch.cat([matrix, offset[..., None]], -1)

    def intensity(self, start: int, stop: int) -> torch.Tensor:
        # The same maps in normalised coordinates, n = D p - 1.
        height, width = self.image.shape
        maps = self.source_maps(start, stop)
        scale = torch.tensor(pixel_scale(height, width), dtype=torch.float64)
        matrix = scale[:, None] * maps[..., :2] / scale
        offset = matrix.sum(-1) + scale * maps[..., 2] - 1
        theta = torch.cat([matrix, offset[..., None]], -1).to(
            device=self.image.device, dtype=torch.float32)
        grid = affine_grid(theta, height, width)
        return sample(self.image, grid).view(stop - start, -1)


@register_effect
class CameraMotion(LightEffect):
    """Camera motion over a still image (``N = 1``).

    Parameters: ``translation`` ``[dx, dy]`` (pixels, right and down),
    ``rotation`` (degrees, counter-clockwise on screen), ``zoom`` (relative
    scale change), each per second or per clip as ``per`` says
    (``'second'`` or ``'clip'``). Default: a slow pan of 500 px/s (an
    assumption, docs/simulator.md).
    """
    name = 'camera_motion'
    defaults = dict(translation=[500.0, 0.0], rotation=0.0, zoom=0.0,
                    per='second')

    def check(self, params):
        params['translation'] = check_pair(self.name, 'translation',
                                           params['translation'])
        for key in ('rotation', 'zoom'):
            params[key] = check_number(self.name, key, params[key])
        check_choice(self.name, 'per', params['per'], ('second', 'clip'))
        return params

    def light(self, intensity, context):
        if intensity.shape[0] != 1:
            raise ValueError(
                f'camera_motion moves a still image (N = 1), got N = '
                f'{intensity.shape[0]} frames; use interpolation for video')
        steps = context.num_steps
        unit = context.readout_hz if self.params['per'] == 'second' else \
            max(steps - 1, 1)
        times = (torch.arange(steps, dtype=torch.float64) -
                 (steps - 1) / 2) / unit
        scale = 1 + times[[0, -1]] * self.params['zoom']
        if scale.min() <= 0:
            raise ValueError(
                f'camera_motion.zoom={self.params["zoom"]} shrinks the image '
                f'to nothing within the clip (scale {float(scale.min()):g})')
        return CameraMotionLight(intensity[0], steps, times,
                                 self.params['translation'],
                                 self.params['rotation'], self.params['zoom'])
