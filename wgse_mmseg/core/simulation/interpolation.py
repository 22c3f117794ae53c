"""The ``interpolation`` effect: how video frames become light per step.

``method='linear'`` is the base model's resampling (:class:`~.light.
LinearLight`), named explicitly. ``method='flow'`` moves content along
optical flow instead of cross-fading it: DIS flow (Kroeger et al., ECCV
2016; OpenCV's ``DISOpticalFlow``) both ways between neighbouring frames,
the flow from an intermediate time ``w`` to each frame approximated as in
Super SloMo (Jiang et al., CVPR 2018, Eq. 4),

    F_w0 = -(1 - w) w F_01 + w^2 F_10,
    F_w1 = (1 - w)^2 F_01 - w (1 - w) F_10,

and the two frames warped there and blended,
``I_w = (1 - w) I_0(x + F_w0) + w I_1(x + F_w1)``. Flow is computed per pair
of frames when the stream reaches it; only one pair's flow is held.
"""
from typing import Dict, Iterator, Tuple

import cv2
import numpy as np
import torch

from .effect import LightEffect, check_choice, register_effect
from .light import LinearLight
from .warp import identity_grid, pixel_scale, sample, warp_block_steps

__all__ = []

_PRESETS: Dict[str, int] = {
    'ultrafast': cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    'fast': cv2.DISOPTICAL_FLOW_PRESET_FAST,
    'medium': cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
}
_MIN_FLOW_SIZE = 16  # DIS needs a frame side of 12 or more


class FlowLight(LinearLight):
    """Frames spread evenly over the steps, interpolated along DIS flow.

    Args:
        intensity: ``(N, H, W)`` float32 in [0, 1], ``N >= 2``.
        num_steps: ``T``.
        preset: DIS preset, ``'ultrafast'``, ``'fast'`` or ``'medium'``.
    """
    linear = False

    def __init__(self, intensity: torch.Tensor, num_steps: int,
                 preset: str):
        super().__init__(intensity, num_steps)
        self.resampling = 'flow'
        self.height, self.width = intensity.shape[1:]
        self._dis = cv2.DISOpticalFlow_create(_PRESETS[preset])
        self._pair = None
        self._flows = None
        self._grid = None

    def blocks(self, max_steps: int) -> Iterator[Tuple[int, int]]:
        return super().blocks(
            warp_block_steps(max_steps, self.height, self.width))

    def _grey(self, frame: torch.Tensor) -> np.ndarray:
        grey = (frame.view(self.height, self.width) * 255).round_()
        return grey.to(torch.uint8).cpu().numpy()

    def _pair_flows(self, index: int, first: torch.Tensor,
                    last: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """``(H, W, 2)`` flows ``F_01`` and ``F_10`` between frames
        ``index`` and ``index + 1``, in normalised units (:mod:`.warp`);
        kept until the next pair."""
        if self._pair != index:
            a, b = self._grey(first), self._grey(last)
            scale = torch.tensor(pixel_scale(self.height, self.width),
                                 device=first.device)
            self._flows = tuple(
                torch.from_numpy(self._flow(x, y)).to(first.device) * scale
                for x, y in ((a, b), (b, a)))
            self._pair = index
        return self._flows

    def _flow(self, source: np.ndarray, target: np.ndarray) -> np.ndarray:
        """``(H, W, 2)`` DIS flow in pixels; frames smaller than DIS takes
        are padded (border repeated) and the flow cropped back."""
        pad_y = max(_MIN_FLOW_SIZE - self.height, 0)
        pad_x = max(_MIN_FLOW_SIZE - self.width, 0)
        if pad_y or pad_x:
            source, target = (cv2.copyMakeBorder(
                image, 0, pad_y, 0, pad_x, cv2.BORDER_REPLICATE)
                              for image in (source, target))
        flow = self._dis.calc(source, target, None)
        return np.ascontiguousarray(flow[:self.height, :self.width])

    def intensity(self, start: int, stop: int) -> torch.Tensor:
        index = self.segment(start)
        first, last = self.segment_frames(index)
        forward, backward = self._pair_flows(index, first, last)
        if self._grid is None:
            self._grid = identity_grid(self.height, self.width,
                                       first.device)
        w = self.fractions(start, stop).view(-1, 1, 1, 1)
        to_first = torch.addcmul(self._grid, -(1 - w) * w, forward)
        to_first.addcmul_(w * w, backward)
        to_last = torch.addcmul(self._grid, (1 - w)**2, forward)
        to_last.addcmul_(-w * (1 - w), backward)
        shape = (self.height, self.width)
        blend = torch.lerp(sample(first.view(shape), to_first),
                           sample(last.view(shape), to_last),
                           w.view(-1, 1, 1))
        return blend.view(stop - start, -1)


@register_effect
class Interpolation(LightEffect):
    """Interpolation of video frames (``N >= 2``) to readout steps.

    Parameters: ``method`` (``'linear'``, the base model's resampling, or
    ``'flow'``) and ``preset`` (DIS preset for ``'flow'``:
    ``'ultrafast'``, ``'fast'`` or ``'medium'``).
    """
    name = 'interpolation'
    defaults = dict(method='linear', preset='medium')

    def check(self, params):
        check_choice(self.name, 'method', params['method'], ('linear',
                                                             'flow'))
        check_choice(self.name, 'preset', params['preset'], tuple(_PRESETS))
        return params

    def light(self, intensity, context):
        if intensity.shape[0] < 2:
            raise ValueError(
                f'interpolation needs video frames (N >= 2), got N = '
                f'{intensity.shape[0]}; use camera_motion to move a still '
                f'image')
        if self.params['method'] == 'linear':
            return LinearLight(intensity, context.num_steps)
        return FlowLight(intensity, context.num_steps, self.params['preset'])
