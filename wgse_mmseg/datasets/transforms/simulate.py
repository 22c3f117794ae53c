"""On-the-fly spike simulation as a data transform: ``SimulateSpikes``.

Trains a spike model from RGB frames: the transform turns a frame (or a
sequence of frames) into a spike stream with
:func:`wgse_mmseg.core.simulation.simulate_spikes`, in the layout
:class:`~wgse_mmseg.datasets.LoadSpikeFromFile` produces, so the rest of a
spike pipeline (``SpikeRandomCrop``, ``SpikeRandomFlip``, ``PackSegInputs``)
follows unchanged. Simulating costs about ``H * W * T`` bytes of output and
a few float passes over it: crop or resize the frames first (MMSeg's
``RandomResize`` / ``RandomCrop`` on the RGB image), then simulate.
"""
import os
import os.path as osp
from typing import Optional

import mmcv
import numpy as np
from cv2 import IMREAD_COLOR
from mmcv.transforms import BaseTransform

from mmseg.registry import TRANSFORMS
from ...argument_checks import check_choice, check_integer, check_number
from ...core.checks import check_device
from ...fileio.images import read_image
from ...limits import MAX_NUM_STEPS
from ...core.seeding import check_seed, derive_seed, draw_seed
from ...core.simulation import parse_effects, simulate_spikes
from ...fileio.scene_files import read_scene_file

__all__ = ['SimulateSpikes']


def _stacked(frames, names) -> np.ndarray:
    """``frames`` of one shape as one array; frames of different sizes
    (or kinds) are a ``ValueError`` naming the first that differs."""
    if not frames:
        raise ValueError('SimulateSpikes: no frames given')
    for frame, name in zip(frames[1:], names[1:]):
        if frame.shape != frames[0].shape:
            raise ValueError(
                f'SimulateSpikes: {name} is shaped {frame.shape} but '
                f'{names[0]} {frames[0].shape}; the frames of one clip share '
                f'one size')
    return np.stack(frames)


@TRANSFORMS.register_module()
class SimulateSpikes(BaseTransform):
    """Simulate a spike stream from ``results``' frames.

    Input, the first present of:

    - ``results['frames']``: a sequence of ``(H, W)`` or ``(H, W, 3)``
      frames (or one ``(N, H, W[, 3])`` array), spread evenly over the
      stream: the middle one of an odd count on the middle step, where
      the label should hold;
    - ``results['frame_paths']``: image files of such a sequence;
    - ``results['img']``: one frame, as ``LoadImageFromFile`` leaves it (a
      still scene, or moved by a ``camera_motion`` effect).

    Args:
        num_steps: ``T``, readout steps to simulate.
        threshold, gain: as in
            :func:`~wgse_mmseg.core.simulation.simulate_spikes`
            (intensity 1.0 fires ``gain / threshold`` spikes per step; the
            REDS convention is ``threshold=1 / 0.6``).
        effects: the scene: a mapping ``effect name -> parameters`` or a
            scene file (docs/simulator.md); ``None`` for the base model.
            Checked when the transform is built.
        seed: ``None`` draws a new stream each call (from NumPy's global
            generator, which mmengine seeds per worker). An integer makes
            each sample's stream deterministic: its seed is derived from
            this one and the sample's ``img_path`` (or ``sample_idx``) by the
            package's one derivation rule, so samples differ
            from each other but not from epoch to epoch.
        channel_order: ``'bgr'`` (``LoadImageFromFile``'s and OpenCV's) or
            ``'rgb'``: the order of colour frames in ``frames`` and ``img``.
            Frames must be ``uint8`` or float in [0, 1].
        device: torch device that runs the simulation.

    Added or replaced keys: ``img`` ``(H, W, T)`` uint8 0/1 (contiguous),
    ``img_shape``, ``ori_shape``, ``num_steps``, and ``simulation`` (the
    simulator's metadata: settings, seed and the effects that ran).
    """

    def __init__(self, num_steps: int, threshold: float = 1.0,
                 gain: float = 1.0, effects=None,
                 seed: Optional[int] = None, channel_order: str = 'bgr',
                 device: str = 'cpu'):
        super().__init__()
        entry = 'SimulateSpikes'
        check_integer(entry, 'num_steps', num_steps, 1, MAX_NUM_STEPS)
        # the simulator's rules, when the transform is built
        check_number(entry, 'threshold', threshold, 0, strict_minimum=True,
                     float32=True)
        check_number(entry, 'gain', gain, 0, float32=True)
        check_seed(seed, entry=entry, allow_none=True)
        check_choice(entry, 'channel_order', channel_order, ('bgr', 'rgb'))
        check_device(entry, 'device', device)
        if isinstance(effects, (str, os.PathLike)):
            effects = read_scene_file(effects)  # once, not per sample
        parse_effects(effects)  # fail at build time, not in a worker
        self.num_steps = num_steps
        self.threshold = threshold
        self.gain = gain
        self.effects = effects
        self.seed = seed
        self.channel_order = channel_order
        self.device = device

    def _frames(self, results: dict) -> np.ndarray:
        """``(N, H, W)`` or ``(N, H, W, 3)`` frames, colour as RGB."""
        if 'frame_paths' in results and 'frames' not in results:
            paths = list(results['frame_paths'])
            return _stacked([mmcv.bgr2rgb(read_image(path, IMREAD_COLOR))
                             for path in paths], paths)
        if 'frames' in results:
            frames = _stacked([np.asarray(f) for f in results['frames']],
                              [f"results['frames'][{index}]" for index in
                               range(len(results['frames']))])
        elif 'img' in results:
            frames = np.asarray(results['img'])[None]
        else:
            raise KeyError(
                "SimulateSpikes needs results['frames'], "
                "results['frame_paths'] or results['img']")
        if frames.ndim == 4 and frames.shape[-1] == 3 and \
                self.channel_order == 'bgr':
            frames = frames[..., ::-1]
        return frames

    def _sample_seed(self, results: dict) -> int:
        if self.seed is None:
            return draw_seed()
        identity = results.get('img_path', results.get('sample_idx'))
        if identity is None:
            return self.seed
        return derive_seed(self.seed, osp.normpath(str(identity)))

    def transform(self, results: dict) -> dict:
        frames = self._frames(results)
        try:
            spikes, meta = simulate_spikes(
                frames, self.num_steps, threshold=self.threshold,
                gain=self.gain, effects=self.effects,
                seed=self._sample_seed(results), device=self.device)
        except ValueError as err:
            source = results.get('img_path', '<frames>')
            raise ValueError(f'{source}: {err}') from err
        results['img'] = np.ascontiguousarray(spikes.transpose(1, 2, 0))
        results['img_shape'] = spikes.shape[1:]
        results['ori_shape'] = spikes.shape[1:]
        results['num_steps'] = self.num_steps
        results['simulation'] = meta
        return results

    def __repr__(self):
        return (f'{self.__class__.__name__}(num_steps={self.num_steps}, '
                f'threshold={self.threshold}, gain={self.gain}, '
                f'effects={self.effects!r}, seed={self.seed}, '
                f'channel_order={self.channel_order!r}, '
                f'device={self.device!r})')
