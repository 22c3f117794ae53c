"""Datasets for image reconstruction from spikes, on the REDS convention.

Both datasets give samples of a ``num_steps``-frame spike window (41 in the
literature) and the sharp grey image at its centre frame, on the intensity
scale of the synthesized REDS spike set: a white pixel fires 0.6 spikes per
step, so the window's spike rate / 0.6 is the image (see
:mod:`wgse_mmseg.core.reconstruction_baselines`).

* :class:`REDSSpikeDataset`: files in the REDS layout
  (``spike/<name>.dat`` beside ``gt/<name>.png``).
* :class:`SimulatedSpikeImageDataset`: any folder of still images, moved
  along random smooth trajectories (shift, rotation, zoom) and turned into
  spikes by :func:`wgse_mmseg.core.simulation.simulate_spikes`, so that a user
  without REDS can train.

In a pipeline the spikes live in ``results['img']`` ``(H, W, T)`` uint8 (as
for segmentation, so ``SpikeRandomCrop``/``SpikeRandomFlip`` apply) and the
ground truth in ``results['gt_image']`` ``(H, W)`` float32 in [0, 1], listed
in ``seg_fields`` so that crops and flips move it with the spikes.
:class:`PackReconstructionInputs` turns both into the model's inputs
``(T, H, W)`` and a data sample holding ``gt_image`` ``(1, H, W)``.
"""
import os.path as osp
from typing import List, Optional, Sequence, Tuple

import numpy as np
import torch
from mmcv.transforms import BaseTransform
from mmengine.dataset import BaseDataset
from mmengine.structures import BaseDataElement, PixelData

from mmseg.registry import DATASETS, TRANSFORMS
from ..argument_checks import (ArgumentError, check_frame_size, check_integer,
                               check_number, check_path, check_read_options,
                               check_text, is_number)
from ..fileio.folder_walk import files_under
from ..limits import MAX_IMAGE_SIDE, MAX_NUM_STEPS, MAX_SAMPLES
from ..core.seeding import check_seed, derive_generator, derive_seed
from ..core.constants import REDS_WHITE_RATE
from ..core.simulation import simulate_spikes
from ..data_generation.views import (load_images, read_grey_image,
                                     render_trajectory)
from .transforms import LoadSpikeFromFile

__all__ = [
    'REDSSpikeDataset', 'SimulatedSpikeImageDataset', 'LoadSpikeImagePair',
    'PackReconstructionInputs'
]


@TRANSFORMS.register_module()
class LoadSpikeImagePair(BaseTransform):
    """Load a spike window and its ground-truth image.

    Reads ``results['gt_path']`` into ``gt_image`` ``(H, W)`` float32 and the
    ``num_steps`` frames of ``results['img_path']`` centred on
    ``results['gt_frame']`` (the middle frame when absent or ``None``) into
    ``img`` ``(H, W, T)``, with :class:`LoadSpikeFromFile`.

    Args:
        num_steps: frames in the window (41 in the literature).
        height, width: frame size of ``.dat`` files; by default the ground
            truth's size (other formats record theirs).
        layout: of ``.npy``/``.npz`` spike files that do not record it
            (``LoadSpikeFromFile``'s ``layout``).
    """

    def __init__(self, num_steps: int = 41, height: Optional[int] = None,
                 width: Optional[int] = None, layout: Optional[str] = None):
        super().__init__()
        entry = 'LoadSpikeImagePair'
        check_integer(entry, 'num_steps', num_steps, 1, MAX_NUM_STEPS)
        check_read_options(entry, height, width, layout)
        if (height is None) != (width is None):
            raise ValueError('LoadSpikeImagePair: height and width go '
                             'together')
        self.num_steps = num_steps
        self.height = height
        self.width = width
        self.layout = layout

    def transform(self, results: dict) -> dict:
        gt = read_grey_image(results['gt_path'])
        # a .dat file records no frame size: the ground truth's by default
        raw = str(results['img_path']).endswith('.dat')
        height, width = ((self.height, self.width) if self.height else
                         gt.shape if raw else (None, None))
        loader = LoadSpikeFromFile(self.num_steps, height, width,
                                   results.get('gt_frame'), self.layout)
        results = loader(results)
        if results['img'].shape[:2] != gt.shape:
            raise ValueError(
                f'{results["img_path"]}: spike frames are '
                f'{results["img"].shape[0]}x{results["img"].shape[1]} but '
                f'the ground truth {results["gt_path"]} is '
                f'{gt.shape[0]}x{gt.shape[1]}')
        results['gt_image'] = gt
        results.setdefault('seg_fields', []).append('gt_image')
        return results

    def __repr__(self):
        return (f'{self.__class__.__name__}(num_steps={self.num_steps}, '
                f'height={self.height}, width={self.width}, '
                f'layout={self.layout!r})')


@TRANSFORMS.register_module()
class PackReconstructionInputs(BaseTransform):
    """Pack a sample for
    :class:`~wgse_mmseg.models.reconstruction.SpikeReconstructor`.

    Returns ``inputs``: ``(T, H, W)`` uint8 tensor, and ``data_samples``: a
    ``BaseDataElement`` with ``gt_image`` (``PixelData`` ``(1, H, W)``
    float32 in [0, 1], when the sample has one) and ``meta_keys`` as
    metainfo.
    """

    def __init__(self, meta_keys: Sequence[str] = (
            'img_path', 'gt_path', 'gt_frame', 'ori_shape', 'img_shape',
            'num_steps', 'flip', 'flip_direction', 'sample_idx')):
        super().__init__()
        if not (isinstance(meta_keys, (list, tuple)) and
                all(isinstance(key, str) for key in meta_keys)):
            raise ArgumentError('PackReconstructionInputs', 'meta_keys',
                                'a sequence of key names (strings)',
                                meta_keys)
        self.meta_keys = tuple(meta_keys)

    def transform(self, results: dict) -> dict:
        spikes = np.ascontiguousarray(results['img'].transpose(2, 0, 1))
        sample = BaseDataElement(metainfo={
            k: results[k] for k in self.meta_keys if k in results})
        if 'gt_image' in results:
            gt = np.ascontiguousarray(results['gt_image'], dtype=np.float32)
            sample.gt_image = PixelData(data=torch.from_numpy(gt[None]))
        return dict(inputs=torch.from_numpy(spikes), data_samples=sample)


@DATASETS.register_module()
class REDSSpikeDataset(BaseDataset):
    """Spike streams with ground-truth frames in the REDS layout::

        data_root/spike/<name>.dat      (e.g. 301 frames of 250x400)
        data_root/gt/<name>.png         (the sharp frame at the centre)

    Each sample is a window of the stream centred on the ground truth's
    frame (``gt_frame``, by default the middle frame ``T // 2``, frame 150
    of a 301-frame stream), loaded by :class:`LoadSpikeImagePair`.

    Args:
        data_prefix: ``spike_path`` and ``gt_path`` folders under
            ``data_root``.
        spike_suffix: spike file extension (``.dat``, ``.spk``, ``.npy``,
            ``.npz``).
        gt_suffix: ground-truth extension.
        gt_frame: frame index of the ground truth in every stream; ``None``
            for the middle frame.
        **kwargs: ``data_root``, ``pipeline``, ``test_mode``, ... of
            mmengine's ``BaseDataset``.
    """

    def __init__(self, data_prefix: dict = dict(spike_path='spike',
                                                gt_path='gt'),
                 spike_suffix: str = '.dat', gt_suffix: str = '.png',
                 gt_frame: Optional[int] = None, **kwargs):
        entry = 'REDSSpikeDataset'
        if not (isinstance(data_prefix, dict) and all(
                isinstance(data_prefix.get(key), str)
                for key in ('spike_path', 'gt_path'))):
            raise ArgumentError(entry, 'data_prefix', "a dict of the "
                                "folders' paths 'spike_path' and 'gt_path'",
                                data_prefix)
        check_text(entry, 'spike_suffix', spike_suffix, empty=False)
        check_text(entry, 'gt_suffix', gt_suffix, empty=False)
        check_integer(entry, 'gt_frame', gt_frame, 0, optional=True)
        self.spike_suffix = spike_suffix
        self.gt_suffix = gt_suffix
        self.gt_frame = gt_frame
        super().__init__(data_prefix=dict(data_prefix), **kwargs)

    def load_data_list(self) -> List[dict]:
        spike_dir = self.data_prefix['spike_path']
        gt_dir = self.data_prefix['gt_path']
        paths = files_under(spike_dir, (self.spike_suffix, ), depth=1)
        if not paths:
            raise FileNotFoundError(
                f'{spike_dir}: no spike files *{self.spike_suffix} (REDS '
                f'layout: spike/<name>{self.spike_suffix} beside '
                f'gt/<name>{self.gt_suffix})')
        data_list = []
        for index, path in enumerate(paths):
            name = osp.basename(path)[:-len(self.spike_suffix)]
            gt_path = osp.join(gt_dir, name + self.gt_suffix)
            if not osp.exists(gt_path):
                raise FileNotFoundError(
                    f'{path}: no ground truth {gt_path} of the same name')
            data_list.append(dict(img_path=path, gt_path=gt_path,
                                  gt_frame=self.gt_frame, sample_idx=index))
        return data_list


def _default_image_dir() -> str:
    """The sample images matplotlib (a dependency of MMSeg) ships.

    ``matplotlib/mpl-data/sample_data``: a photograph (``grace_hopper.jpg``,
    512x600) and two small graphics; the embedded default training images.
    """
    import matplotlib
    return osp.join(matplotlib.get_data_path(), 'sample_data')


#: a ``(low, high)`` range of positive numbers
def _check_range(entry: str, name: str, value) -> None:
    """A ``(low, high)`` range of finite numbers ``0 < low <= high``."""
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and
            all(is_number(v, 0, strict_minimum=True) for v in value) and
            value[0] <= value[1]):
        raise ArgumentError(entry, name, '(low, high) with low <= high, '
                            'each a finite number > 0', value)


@DATASETS.register_module()
class SimulatedSpikeImageDataset(BaseDataset):
    """Spike windows simulated from still images moved along trajectories.

    Sample ``i`` is drawn from ``derive_generator(seed, i)`` and its spikes
    from ``derive_seed(seed, i, 'spikes')`` (the package's one seed
    derivation rule), so the set is the same on every run: an image (chosen
    with probability proportional to its area), a view of ``crop_size`` moved
    along a random trajectory, a random brightness (gain in
    ``gain_range``, gamma log-uniform in ``gamma_range``), then
    :func:`~wgse_mmseg.core.simulation.simulate_spikes` with
    ``threshold = 1 / white_rate`` (the REDS scale). The ground truth is the
    centre frame ``num_steps // 2``. Spikes and ground truth are made on the
    fly, in the data loader.

    Args:
        image_dir: folder of images (searched recursively, colour -> grey);
            ``None`` for the sample images matplotlib ships. Images are read
            once into memory, downscaled to at most ``max_side`` pixels per
            side.
        num_samples: length of the dataset.
        crop_size: ``(h, w)`` of each sample.
        num_steps: spike frames per sample.
        seed: seed of the whole set; give a validation set another seed.
        white_rate: spikes per step of a white pixel (REDS: 0.6).
        max_speed, max_rotation, max_zoom, scale_range: trajectory limits
            (view pixels and radians per step, zoom per step, the range of
            the view's scale).
        gain_range, gamma_range: brightness augmentation; the ground truth
            is the augmented image.
        max_side: longest image side kept in memory.
        **kwargs: ``pipeline``, ``test_mode``, ... of ``BaseDataset``.
    """

    def __init__(self, image_dir: Optional[str] = None,
                 num_samples: int = 10000,
                 crop_size: Tuple[int, int] = (64, 64), num_steps: int = 41,
                 seed: int = 0, white_rate: float = REDS_WHITE_RATE,
                 max_speed: float = 0.6, max_rotation: float = 0.002,
                 max_zoom: float = 0.003,
                 scale_range: Tuple[float, float] = (0.7, 2.5),
                 gain_range: Tuple[float, float] = (0.5, 1.0),
                 gamma_range: Tuple[float, float] = (0.7, 1.4),
                 max_side: int = 1024, **kwargs):
        entry = 'SimulatedSpikeImageDataset'
        check_path(entry, 'image_dir', image_dir, optional=True)
        check_integer(entry, 'num_samples', num_samples, 1, MAX_SAMPLES)
        check_frame_size(entry, 'crop_size', crop_size)
        check_integer(entry, 'num_steps', num_steps, 1, MAX_NUM_STEPS)
        check_seed(seed, entry=entry)
        check_number(entry, 'white_rate', white_rate, 0, strict_minimum=True)
        for name, value in (('max_speed', max_speed),
                            ('max_rotation', max_rotation),
                            ('max_zoom', max_zoom)):
            check_number(entry, name, value, 0)
        for name, value in (('scale_range', scale_range),
                            ('gain_range', gain_range),
                            ('gamma_range', gamma_range)):
            _check_range(entry, name, value)
        check_integer(entry, 'max_side', max_side, 1, MAX_IMAGE_SIDE)
        self.image_dir = image_dir or _default_image_dir()
        self.image_paths, self.images = load_images(self.image_dir,
                                                    max_side)
        areas = np.array([im.size for im in self.images], np.float64)
        self.image_probs = areas / areas.sum()
        self.num_samples = num_samples
        self.crop_size = tuple(crop_size)
        self.num_steps = num_steps
        self.seed = seed
        self.white_rate = white_rate
        self.trajectory = dict(max_speed=max_speed, max_rotation=max_rotation,
                               max_zoom=max_zoom,
                               scale_range=tuple(scale_range))
        self.gain_range = tuple(gain_range)
        self.gamma_range = tuple(gamma_range)
        super().__init__(**kwargs)

    def full_init(self) -> None:
        # Samples are drawn by index: no data list to load or serialize.
        self._fully_initialized = True

    def __len__(self) -> int:
        return self.num_samples

    def get_data_info(self, idx: int) -> dict:
        return dict(sample_idx=idx)

    def simulate(self, index: int) -> dict:
        """Sample ``index`` as pipeline results (``img``, ``gt_image``)."""
        rng = derive_generator(self.seed, index)
        choice = rng.choice(len(self.images), p=self.image_probs)
        frames = render_trajectory(self.images[choice], self.crop_size,
                                   self.num_steps, rng, **self.trajectory)
        gamma = np.exp(rng.uniform(*np.log(self.gamma_range)))
        frames = rng.uniform(*self.gain_range) * np.clip(frames, 0, 1)**gamma
        spikes, _ = simulate_spikes(frames, self.num_steps,
                                    threshold=1 / self.white_rate,
                                    seed=derive_seed(self.seed, index,
                                                     'spikes'))
        return dict(
            img=np.ascontiguousarray(spikes.transpose(1, 2, 0)),
            gt_image=frames[self.num_steps // 2],
            seg_fields=['gt_image'],
            img_path=f'<simulated sample {index} of '
            f'{self.image_paths[choice]}>',
            img_shape=self.crop_size, ori_shape=self.crop_size,
            num_steps=self.num_steps, sample_idx=index)

    def prepare_data(self, idx: int):
        return self.pipeline(self.simulate(idx))
