"""Cityscapes to Spike-Cityscapes: find the samples, map the labels, simulate.

Input, a Cityscapes root::

    leftImg8bit/<split>/<city>/<stem>_leftImg8bit.png          RGB
    gtFine/<split>/<city>/<stem>_gtFine_labelTrainIds.png
                       or <stem>_gtFine_labelIds.png
    leftImg8bit_sequence/<split>/<city>/<stem>_leftImg8bit.png optional

with ``<stem> = <city>_<seq>_<frame>``; a sequence snippet holds 30 frames,
the annotated one 20th.

Output, the layout :class:`~wgse_mmseg.datasets.SpikeCityscapesDataset`
reads::

    spike/<split>/<city>/<stem>_spike.spk               (T, H, W) 0/1 spikes
    spike/<split>/<city>/<stem>_spike.json              the sample's marker
    gtFine/<split>/<city>/<stem>_gtFine_labelTrainIds.png   (H, W) train ids

Time span. A spike camera reads out at 40 kHz, so ``T`` steps last
``T / 40000`` s (3.2 ms for ``T = 129``), while Cityscapes' sequence runs at
17 Hz (59 ms between frames). When ``leftImg8bit_sequence`` holds the
frames ``frame - K .. frame + K`` (``K = frames_around``), those ``2K + 1``
frames are spread evenly over the ``T`` steps and the simulator interpolates
between them along DIS optical flow: the stream covers ``2K / 17`` s of
scene time, played ``(2K / 17) / (T / 40000)`` times faster than real time
(x36 for ``K = 1``, ``T = 129``), with the annotated frame at the middle
step, where the label holds. Without those frames (or with ``K = 0``) the
scene's static model is used: the annotated frame alone, optionally moved
by a ``camera_motion`` effect.

Complete or absent. A sample's json is its marker: the settings that made it
(the recipe) and the size and SHA-256 of the spike file and label its run
wrote. A sample is done only when its marker exists, holds the current
recipe and matches both files (and SpikeCityscapesDataset serves only
samples whose marker matches); a run removes the marker before it writes a
sample's files and writes it last, each file atomically, so a run killed at
any point leaves that sample without a marker, and the next run (with any
settings) redoes it. Temporary files are named after their target
(:func:`~wgse_mmseg.fileio.atomic.atomic_output`), and a run removes only
those of its own samples. Each sample's seed is derived from the base seed and
its name (:func:`~wgse_mmseg.core.seeding.derive_seed`), so reruns give
identical files.

One writer per shard. A conversion owns ``out_dir``
(:func:`~wgse_mmseg.fileio.locks.own_folder`, job ``shard-K-of-N``):
a second process converting the same shard into it is refused at once,
naming the first, or waits (``wait``, ``--wait``); a link inside
``out_dir`` is never written through (a linked folder is refused, a link
at a sample's file replaced).

Shards. ``convert_cityscapes(..., shard=Shard(K, N))`` (``--shard K/N``)
converts every ``N``-th sample of the sorted list from the ``K``-th on
(:mod:`.shards`): the shards of a job are disjoint, may run at the same time
on machines sharing ``out_dir`` (``tools/slurm_convert.sh``), and together
write the files one run writes, byte for byte, since nothing a sample's
files hold depends on the other samples.
"""
import contextlib
import json
import multiprocessing
import os
import os.path as osp
from dataclasses import dataclass, field
from functools import partial
from typing import Dict, Optional, Sequence, Tuple

import numpy as np
from tqdm import tqdm

from ..argument_checks import (ArgumentError, check_flag, check_integer,
                               check_number, check_path, is_choice)
from ..core.constants import READOUT_HZ, REDS_THRESHOLD
from ..core.seeding import check_seed, derive_seed
from ..errors import excerpt
from ..fileio.atomic import temporaries_of
from ..fileio.bounded_reads import parse_json
from ..fileio.images import read_image, write_png
from ..fileio.locks import own_folder
from ..fileio.markers import invalidate, is_complete, write_marker
from ..fileio.output_folder import OwnedFolder
from ..fileio.spike_files import save_spikes
from ..limits import MAX_IMAGE_SIDE, MAX_NUM_STEPS, MAX_SAMPLES, MAX_WORKERS
from .cityscapes_layout import (ANNOTATED_INDEX, CITYSCAPES_FPS,
                                CITYSCAPES_SPLITS, KNOWN_TRAIN_IDS,
                                SNIPPET_LENGTH, CityscapesSample, find_samples,
                                labelids_to_trainids, resize_nearest)
from .shards import SHARD, WHOLE, Shard

__all__ = ['ConversionSettings', 'convert_cityscapes']


@dataclass(frozen=True)
class ConversionSettings:
    """What a converted sample depends on besides its source files.

    Args:
        height, width: output frame size (Cityscapes is 1024x2048).
        num_steps: ``T``, spike readout steps per sample.
        threshold: firing threshold (REDS convention ``1 / 0.6``).
        frames_around: ``K``; the sequence frames ``frame - K .. frame + K``
            span the stream (``0``: always the static model).
        scene: extra simulator effects, name -> parameters, for every sample;
            ``interpolation`` applies only to sequence samples (default
            ``{'method': 'flow'}``), ``camera_motion`` only to static ones.
        seed: base seed; each sample's seed also depends on its name.
    """
    height: int = 512
    width: int = 1024
    num_steps: int = 129
    threshold: float = REDS_THRESHOLD
    frames_around: int = 1
    scene: Dict[str, Optional[dict]] = field(default_factory=dict)
    seed: int = 0

    def __post_init__(self):
        entry = 'ConversionSettings'
        check_integer(entry, 'height', self.height, 1, MAX_IMAGE_SIDE)
        check_integer(entry, 'width', self.width, 1, MAX_IMAGE_SIDE)
        check_integer(entry, 'num_steps', self.num_steps, 1, MAX_NUM_STEPS)
        check_number(entry, 'threshold', self.threshold, 0,
                     strict_minimum=True, float32=True)
        check_integer(entry, 'frames_around', self.frames_around, 0,
                      SNIPPET_LENGTH - 1 - ANNOTATED_INDEX)
        if not isinstance(self.scene, dict):
            raise ArgumentError(entry, 'scene', 'a dict of simulator '
                                'effects, name -> parameters', self.scene)
        check_seed(self.seed, entry=entry)


def _read(path: str, flags: int) -> np.ndarray:
    return read_image(path, flags)


def _train_id_label(sample: CityscapesSample, height: int,
                    width: int, image_shape: Tuple[int, int]) -> np.ndarray:
    """The sample's ``(height, width)`` ``uint8`` train-id label."""
    import cv2
    label = _read(sample.label, cv2.IMREAD_UNCHANGED)
    if label.ndim != 2 or label.dtype != np.uint8:
        raise ValueError(
            f'{sample.label}: expected a single-channel 8-bit label image, '
            f'got shape {label.shape} of {label.dtype}')
    if label.shape != image_shape:
        raise ValueError(
            f'{sample.label}: label is {label.shape[0]}x{label.shape[1]} '
            f'but its image {sample.image} is '
            f'{image_shape[0]}x{image_shape[1]}')
    if sample.label_kind == 'labelIds':
        label = labelids_to_trainids(label, sample.label)
    elif not KNOWN_TRAIN_IDS[label].all():
        bad = sorted(set(label[~KNOWN_TRAIN_IDS[label]].tolist()))
        raise ValueError(
            f'{sample.label}: values {bad[:10]} are not Cityscapes train '
            f'ids (0..18, 255)')
    return resize_nearest(label, height, width)


def _rgb_frames(sample: CityscapesSample, height: int,
                width: int) -> Tuple[np.ndarray, Tuple[int, int]]:
    """``(N, height, width, 3)`` ``uint8`` RGB frames and the source size:
    the sequence, or the annotated frame alone."""
    import cv2
    frames, size = [], None
    for path in sample.sequence or (sample.image, ):
        image = _read(path, cv2.IMREAD_COLOR)
        if size is None:
            size = image.shape[:2]
        elif image.shape[:2] != size:
            raise ValueError(
                f'{path}: frame is {image.shape[0]}x{image.shape[1]} but '
                f'{sample.image} is {size[0]}x{size[1]}')
        image = cv2.resize(image, (width, height),
                           interpolation=cv2.INTER_AREA)
        frames.append(cv2.cvtColor(image, cv2.COLOR_BGR2RGB))
    return np.stack(frames), size


def sample_effects(sample: CityscapesSample,
                   scene: Dict[str, Optional[dict]]
                   ) -> Dict[str, Optional[dict]]:
    """Simulator effects for ``sample``: name -> parameters.

    A sequence sample gets ``interpolation`` (``{'method': 'flow'}`` unless
    the scene sets it) and the scene's effects but ``camera_motion``, which
    its frames already hold; a static sample gets the scene's effects but
    ``interpolation``.
    """
    if sample.sequence:
        effects = dict(interpolation=scene.get('interpolation',
                                               {'method': 'flow'}))
        skip = ('interpolation', 'camera_motion')
    else:
        effects, skip = {}, ('interpolation', )
    effects.update(
        (name, params) for name, params in scene.items() if name not in skip)
    return effects


def output_paths(out_dir: str, sample: CityscapesSample) -> Dict[str, str]:
    """``spike``, ``meta`` and ``label`` paths of ``sample`` in ``out_dir``."""
    spike_dir = osp.join(out_dir, 'spike', sample.split, sample.city)
    return dict(
        spike=osp.join(spike_dir, f'{sample.stem}_spike.spk'),
        meta=osp.join(spike_dir, f'{sample.stem}_spike.json'),
        label=osp.join(out_dir, 'gtFine', sample.split, sample.city,
                       f'{sample.stem}_gtFine_labelTrainIds.png'))


def _recipe(sample: CityscapesSample, settings: ConversionSettings,
            root: str) -> dict:
    """Everything a sample's files depend on, as JSON values."""
    scene_seconds = 2 * settings.frames_around / CITYSCAPES_FPS
    recipe = dict(
        model='sequence' if sample.sequence else 'static',
        sources=dict(
            image=osp.relpath(sample.image, root),
            label=osp.relpath(sample.label, root),
            label_kind=sample.label_kind,
            sequence=[osp.relpath(p, root) for p in sample.sequence]),
        height=settings.height, width=settings.width,
        num_steps=settings.num_steps, threshold=settings.threshold,
        seed=derive_seed(settings.seed, sample.stem),
        effects=sample_effects(sample, settings.scene),
        time_span=dict(
            readout_seconds=settings.num_steps / READOUT_HZ,
            scene_seconds=scene_seconds if sample.sequence else 0.0,
            frames_around=settings.frames_around if sample.sequence else 0))
    return json.loads(json.dumps(recipe))


def _marked_files(paths: Dict[str, str]) -> Dict[str, str]:
    """The files of a sample that its marker covers."""
    return dict(spike=paths['spike'], label=paths['label'])


def _jsonable(value):
    """JSON form of the NumPy values a simulator's metadata may hold."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f'{type(value).__name__} is not JSON serialisable')


def convert_sample(sample: CityscapesSample, root: str, out_dir: str,
                   settings: ConversionSettings) -> str:
    """Write one sample's spike stream, label and metadata.

    Everything is computed before anything is written; then the marker is
    removed, the label and the spikes are written, and the marker (recipe,
    size and SHA-256 of the bytes written to both files, the simulator's
    metadata) last, each file atomically (:mod:`wgse_mmseg.fileio.markers`).
    Returns ``'skipped'`` when the sample is already done, else its model,
    ``'sequence'`` or ``'static'``. A link at a sample's file is replaced, a
    linked folder refused
    (:class:`~wgse_mmseg.fileio.output_folder.OwnedFolder`).
    """
    from ..core.simulation import simulate_spikes  # torch, where it runs
    owned = OwnedFolder(out_dir)
    paths = {name: owned.file(path)
             for name, path in output_paths(out_dir, sample).items()}
    recipe = _recipe(sample, settings, root)
    if is_complete(paths['meta'], recipe, _marked_files(paths)):
        return 'skipped'
    frames, size = _rgb_frames(sample, settings.height, settings.width)
    label = _train_id_label(sample, settings.height, settings.width, size)
    spikes, simulation = simulate_spikes(
        frames, settings.num_steps, threshold=settings.threshold,
        effects=recipe['effects'], seed=recipe['seed'])
    invalidate(paths['meta'])
    written = dict(label=write_png(paths['label'], label),
                   spike=save_spikes(paths['spike'], spikes))
    write_marker(paths['meta'], recipe, written,
                 dict(simulation=simulation), default=_jsonable)
    return recipe['model']


def _remove_stale_temporaries(out_dir: str,
                              samples: Sequence[CityscapesSample]) -> None:
    """Remove the temporary files a killed run left for ``samples``
    (``atomic_output``'s), and no other: another shard may be writing its
    own beside them."""
    paths = [path for sample in samples
             for path in output_paths(out_dir, sample).values()]
    for path in temporaries_of(paths):
        os.remove(path)


def _init_worker() -> None:
    """One thread per worker process: the pool provides the parallelism."""
    import cv2
    import torch
    torch.set_num_threads(1)
    cv2.setNumThreads(1)


def convert_cityscapes(root: str, out_dir: str,
                       settings: Optional[ConversionSettings] = None,
                       splits: Sequence[str] = ('train', 'val'),
                       nproc: int = 1, limit: Optional[int] = None,
                       progress: bool = True,
                       shard: Shard = WHOLE,
                       wait: bool = False) -> Dict[str, int]:
    """Convert the Cityscapes ``root`` into Spike-Cityscapes at ``out_dir``.

    Args:
        root: Cityscapes root (``leftImg8bit/``, ``gtFine/``, optionally
            ``leftImg8bit_sequence/``).
        out_dir: output root.
        settings: output size, ``T``, threshold, time span, effects, seed.
        splits: Cityscapes splits to convert.
        nproc: worker processes (1: in this process). They are started
            fresh (``spawn``), never forked from this process: a fork of a
            process with other threads (a notebook's, a progress bar's
            monitor) can deadlock or crash in the child.
        limit: convert at most this many samples per split (first by name).
        progress: show a progress bar.
        shard: ``Shard(K, N)``: only the samples at positions ``K - 1``,
            ``K - 1 + N``, ... of the job's list (``splits`` in order, each
            sorted by name, cut to ``limit``); the ``N`` shards of a job
            (same root, settings, splits and limit) together convert it.
        wait: wait for another process converting this shard into
            ``out_dir`` instead of raising ``OutputFolderError``.

    Returns:
        How many samples were made from a ``'sequence'``, made by the
        ``'static'`` model, and ``'skipped'`` as already done.
    """
    entry = 'convert_cityscapes'
    check_path(entry, 'root', root)
    check_path(entry, 'out_dir', out_dir)
    if settings is not None and not isinstance(settings, ConversionSettings):
        raise ArgumentError(entry, 'settings', 'a ConversionSettings or None',
                            settings)
    if not (isinstance(splits, (list, tuple)) and splits and
            all(is_choice(split, CITYSCAPES_SPLITS) for split in splits)):
        raise ArgumentError(entry, 'splits', f'a non-empty sequence of '
                            f'{list(CITYSCAPES_SPLITS)}', splits)
    check_integer(entry, 'nproc', nproc, 1, MAX_WORKERS)
    check_integer(entry, 'limit', limit, 1, MAX_SAMPLES, optional=True)
    check_flag(entry, 'progress', progress)
    SHARD.check(shard, entry, 'shard')
    check_flag(entry, 'wait', wait)
    settings = settings or ConversionSettings()
    samples = find_samples(root, splits, settings.frames_around)
    if limit is not None:
        samples = [s for split in splits
                   for s in [s for s in samples if s.split == split][:limit]]
    samples = Shard(*shard).select(samples)
    convert = partial(convert_sample, root=root, out_dir=out_dir,
                      settings=settings)
    counts = dict(sequence=0, static=0, skipped=0)
    job = 'shard-{}-of-{}'.format(*shard)
    with own_folder(out_dir, job, wait), contextlib.ExitStack() as stack:
        _remove_stale_temporaries(out_dir, samples)
        if nproc == 1:
            outcomes = map(convert, samples)
        else:
            pool = stack.enter_context(
                multiprocessing.get_context('spawn').Pool(
                    nproc, _init_worker))
            outcomes = pool.imap_unordered(convert, samples)
        for outcome in tqdm(outcomes, total=len(samples),
                            desc=f'Spike-Cityscapes {Shard(*shard)}',
                            disable=not progress):
            counts[outcome] += 1
    return counts


def load_scene(value: Optional[str]) -> Dict[str, Optional[dict]]:
    """Simulator effects from a JSON/YAML scene file or inline JSON.

    Returns the mapping effect name -> parameters (``None`` or ``{}``: the
    effect's defaults; empty for ``value=None``), each effect checked by the
    simulator's parser so that a typo fails before any conversion.
    """
    from ..core.simulation import parse_effects
    from ..fileio.scene_files import read_scene_file
    if value is None:
        return {}
    if osp.isfile(value):
        scene = read_scene_file(value)
    else:
        try:
            scene = parse_json(value, 'the command line', 'scene')
        except ValueError as err:
            raise ValueError(f'scene {excerpt(value)} is neither a file nor '
                             f'inline JSON: {err}') from err
        if not isinstance(scene, dict):
            raise ValueError(
                f'scene {value!r} must map effect names to parameters, '
                f'e.g. {{"shot_noise": {{}}}}')
    for name, params in scene.items():  # one by one: two light effects
        parse_effects({name: params})  # are allowed, routed per sample
    return scene
