"""The camera trajectory, and the ``camera_motion`` effect that uses it.

One trajectory serves every still-image motion in the package (this effect
and :class:`~wgse_mmseg.datasets.SimulatedSpikeImageDataset`). At time
``tau`` from the reference point, content at ``q`` (source pixels from
``source_centre``, ``y`` down) appears in the view at

    p = view_centre + s(tau) R(phi(tau)) q / base_scale + shift(tau),
    s(tau) = 1 + tau * zoom,   phi(tau) = base_angle + tau * rotation,
    shift(tau) = tau * translation + tau**2 / 2 * acceleration,

``R(phi)`` turning content counter-clockwise on screen and ``base_scale``
counting source pixels per view pixel (:func:`trajectory_source_maps`).

The effect warps the whole image (``base_scale = 1``, no base angle) along a
trajectory centred on the middle step, where it is seen as it is (so its
label holds there, as for video, whose middle frame sits on the middle
step). ``tau`` is in seconds (``per='second'``: ``translation`` in px/s,
``rotation`` in deg/s, ``zoom`` in 1/s) or in clip lengths (``per='clip'``:
the totals from the first step to the last). Outside the image the border
is repeated.
"""
import math
from typing import Iterator, Sequence, Tuple

import torch

from .effect import (LightEffect, check_choice, check_number, check_pair,
                     register_effect)
from .light import Light
from .warp import affine_grid, pixel_scale, sample, warp_block_steps

__all__ = []


def trajectory_source_maps(times: torch.Tensor, view_size: Tuple[int, int],
                           source_centre: Sequence[float],
                           translation: Sequence[float] = (0.0, 0.0),
                           acceleration: Sequence[float] = (0.0, 0.0),
                           rotation: float = 0.0, zoom: float = 0.0,
                           base_angle: float = 0.0,
                           base_scale: float = 1.0) -> torch.Tensor:
    """Where each view pixel looks in the source image along a trajectory.

    The inverse of the module's motion model: view pixel ``p`` of step ``k``
    shows the source at ``M_k p + b_k``, with
    ``M_k = base_scale R(-phi) / s`` and
    ``b_k = source_centre - M_k (view_centre + shift)``.

    Args:
        times: ``(K,)`` ``tau`` of each step (0 at the reference point).
        view_size: ``(h, w)`` of the view; its centre is
            ``((w - 1) / 2, (h - 1) / 2)``.
        source_centre: ``(x, y)`` source point at the view centre at
            ``tau = 0``.
        translation: ``(dx, dy)`` view pixels per unit of ``tau``.
        acceleration: ``(ax, ay)`` view pixels per unit of ``tau`` squared.
        rotation: radians per unit of ``tau``, counter-clockwise on screen.
        zoom: relative scale change per unit of ``tau``.
        base_angle: radians at ``tau = 0``.
        base_scale: source pixels per view pixel at ``tau = 0``.

    Returns:
        ``(K, 2, 3)`` float64 maps ``[M_k | b_k]`` in pixels.
    """
    height, width = view_size
    tau = torch.as_tensor(times, dtype=torch.float64)
    scale = 1 + tau * zoom
    if scale.numel() and scale.min() <= 0:
        raise ValueError(f'zoom={zoom} shrinks the view to nothing within '
                         f'the trajectory (scale {float(scale.min()):g})')
    angle = base_angle + tau * rotation
    cos = base_scale * torch.cos(angle) / scale
    sin = base_scale * torch.sin(angle) / scale
    # R(-phi) with R(phi) turning content counter-clockwise on screen (y
    # down): R(-phi) = [[cos, -sin], [sin, cos]]
    matrix = torch.stack([torch.stack([cos, -sin], -1),
                          torch.stack([sin, cos], -1)], -2)
    shift = (tau[:, None] * torch.tensor(translation, dtype=torch.float64) +
             tau[:, None]**2 / 2 *
             torch.tensor(acceleration, dtype=torch.float64))
    view_centre = torch.tensor([(width - 1) / 2, (height - 1) / 2],
                               dtype=torch.float64)
    offset = (torch.tensor(source_centre, dtype=torch.float64) -
              (matrix @ (view_centre + shift)[..., None])[..., 0])
    return torch.cat([matrix, offset[..., None]], -1)


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
        return trajectory_source_maps(
            self.times[start:stop], (height, width),
            ((width - 1) / 2, (height - 1) / 2), self.translation,
            rotation=self.rotation, zoom=self.zoom)

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
