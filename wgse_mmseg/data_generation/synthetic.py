"""A small Spike-Cityscapes-format dataset drawn procedurally, for CPU runs.

Each sample is a street-like scene (sky, buildings with windows, vegetation,
poles and signs, sidewalk, road with lane marks) with cars and pedestrians
moving across it. The scene is rendered at several instants, turned into a
spike stream by :func:`wgse_mmseg.core.simulation.simulate_spikes`, and
labelled with Cityscapes train ids at the middle instant, where the stream is
centred. Everything is seeded: scene ``i`` is drawn from
``derive_generator(seed, i)`` and its spikes from
``derive_seed(seed, i, 'spikes')`` (:mod:`wgse_mmseg.core.seeding`), so the
same arguments give the same files.
"""
import os.path as osp
from typing import Tuple

import numpy as np
from tqdm import tqdm

from ..argument_checks import (check_flag, check_integer, check_number,
                               check_path)
from ..limits import (MAX_IMAGE_SIDE, MAX_NUM_STEPS, MAX_SAMPLES,
                      check_allocation)
from ..core.constants import REDS_THRESHOLD
from ..fileio.spike_files import save_spikes
from ..fileio.images import write_png
from ..fileio.markers import invalidate, is_complete, write_marker
from ..fileio.locks import own_folder
from ..core.seeding import check_seed, derive_generator, derive_seed

__all__ = ['make_synthetic_dataset']

# Cityscapes train ids of the classes the scenes draw.
ROAD, SIDEWALK, BUILDING, POLE, SIGN, VEGETATION, SKY, PERSON, CAR = (
    0, 1, 2, 5, 7, 8, 10, 11, 13)


def _box(image, label, y0, y1, x0, x1, value, class_id):
    y0, y1 = max(int(y0), 0), max(int(y1), 0)
    x0, x1 = max(int(x0), 0), max(int(x1), 0)
    image[y0:y1, x0:x1] = value
    label[y0:y1, x0:x1] = class_id


def _background(rng: np.random.Generator, height: int,
                width: int) -> Tuple[np.ndarray, np.ndarray, int]:
    """Static part of a scene: intensity, label and the horizon row."""
    import cv2  # where drawn: the command line's --help needs none
    image = np.empty((height, width), np.float64)
    label = np.empty((height, width), np.uint8)
    horizon = int(height * rng.uniform(0.45, 0.6))
    curb = horizon + int((height - horizon) * rng.uniform(0.15, 0.3))
    _box(image, label, 0, horizon, 0, width, rng.uniform(0.8, 0.95), SKY)
    x = 0
    while x < width:  # a row of buildings with lit windows
        w = max(int(width * rng.uniform(0.12, 0.3)), 1)
        top = int(horizon * rng.uniform(0.1, 0.6))
        _box(image, label, top, horizon, x, x + w, rng.uniform(0.3, 0.55),
             BUILDING)
        for wy in range(top + 4, horizon - 6, 10):  # none on tiny frames
            for wx in range(x + 3, x + w - 6, 9):
                image[wy:wy + 4, wx:wx + 4] = rng.uniform(0.6, 0.9)
        x += w
    for _ in range(rng.integers(1, 4)):  # trees in front of the buildings
        cx, cy = rng.uniform(0, width), horizon * rng.uniform(0.65, 0.95)
        axes = (1 + int(width * rng.uniform(0.03, 0.1)),
                1 + int(height * rng.uniform(0.06, 0.2)))
        mask = np.zeros_like(label)
        cv2.ellipse(mask, (int(cx), int(cy)), axes, 0, 0, 360, 1, -1)
        texture = 0.3 + 0.1 * rng.random((height, width))
        image[mask > 0] = texture[mask > 0]
        label[mask > 0] = VEGETATION
    _box(image, label, horizon, curb, 0, width, rng.uniform(0.5, 0.65),
         SIDEWALK)
    _box(image, label, curb, height, 0, width, rng.uniform(0.15, 0.3), ROAD)
    lane = curb + (height - curb) // 2
    for x in range(int(rng.uniform(0, 20)), width, 30):  # lane marks
        image[lane:lane + 2, x:x + 14] = 0.9
    for _ in range(rng.integers(1, 3)):  # poles carrying signs
        x = int(rng.uniform(0, width - 4))
        top = int(horizon * rng.uniform(0.3, 0.7))
        _box(image, label, top, curb, x, x + 3, 0.12, POLE)
        _box(image, label, top - 8, top, x - 4, x + 7, 0.95, SIGN)
    return image, label, curb


def render_street_scene(rng: np.random.Generator, height: int, width: int,
                        num_frames: int) -> Tuple[np.ndarray, np.ndarray]:
    """Render ``num_frames`` instants of one moving street scene.

    Returns:
        ``(frames, label)``: ``(N, H, W)`` float intensities in [0, 1] and the
        ``(H, W)`` ``uint8`` train-id label of the middle instant.
    """
    import cv2
    background, background_label, curb = _background(rng, height, width)
    movers = []
    for _ in range(rng.integers(1, 4)):
        h = int(rng.uniform(0.12, 0.22) * height)
        movers.append(dict(
            cls=CAR, h=h, w=int(h * rng.uniform(1.8, 2.6)),
            y=int(rng.uniform(curb, height - h / 2)),
            x=rng.uniform(0, width), v=rng.uniform(-6, 6),
            value=rng.uniform(0.05, 0.85)))
    for _ in range(rng.integers(0, 4)):
        h = int(rng.uniform(0.15, 0.3) * height)
        movers.append(dict(
            cls=PERSON, h=h, w=max(h // 3, 3), y=curb - rng.uniform(0, 5),
            x=rng.uniform(0, width), v=rng.uniform(-2, 2),
            value=rng.uniform(0.55, 0.75)))
    movers.sort(key=lambda m: m['y'])  # nearer objects drawn last
    check_allocation(num_frames * height * width * 8,
                     f'the {num_frames} x {height} x {width} float64 frames '
                     f'of a synthetic scene', 'num_frames or the image size')
    frames = np.empty((num_frames, height, width), np.float64)
    label = None
    for index in range(num_frames):
        image, lab = background.copy(), background_label.copy()
        for m in movers:
            x = m['x'] + m['v'] * index
            if m['cls'] == CAR:
                _box(image, lab, m['y'] - m['h'], m['y'], x, x + m['w'],
                     m['value'], CAR)
                _box(image, lab, m['y'] - 0.8 * m['h'], m['y'] - 0.5 * m['h'],
                     x + 0.2 * m['w'], x + 0.8 * m['w'], 0.85, CAR)
            else:
                mask = np.zeros_like(lab)
                cv2.ellipse(mask, (int(x), int(m['y'] - m['h'] / 2)),
                            (m['w'] // 2, m['h'] // 2), 0, 0, 360, 1, -1)
                image[mask > 0], lab[mask > 0] = m['value'], PERSON
        frames[index] = image
        if index == num_frames // 2:
            label = lab
    return np.clip(frames, 0, 1), label


#: the most frames a scene is rendered in
MAX_FRAMES = 1024


def make_synthetic_dataset(out_dir: str, num_train: int = 48,
                           num_val: int = 12, height: int = 128,
                           width: int = 256, num_steps: int = 41,
                           num_frames: int = 5,
                           threshold: float = REDS_THRESHOLD, seed: int = 0,
                           progress: bool = True,
                           wait: bool = False) -> int:
    """Write a Spike-Cityscapes-layout dataset to ``out_dir``.

    Files: ``spike/{train,val}/synth/synth_<scene>_000019_spike.spk``,
    ``gtFine/{train,val}/synth/synth_<scene>_000019_gtFine_labelTrainIds.png``
    and the sample's marker ``..._spike.json`` (the settings and the size
    and SHA-256 of the bytes written, written last). A sample whose
    marker matches these settings and its files is kept, so an interrupted
    run resumes; any other is made again. The run owns ``out_dir``
    (an output folder with one writer): another run into
    it is refused naming this one, or waits for it with ``wait``; a link
    at a sample's file is replaced, a linked folder refused. Returns the
    number of samples written now.
    """
    entry = 'make_synthetic_dataset'
    check_path(entry, 'out_dir', out_dir)
    check_integer(entry, 'num_train', num_train, 0, MAX_SAMPLES)
    check_integer(entry, 'num_val', num_val, 0, MAX_SAMPLES)
    check_integer(entry, 'height', height, 1, MAX_IMAGE_SIDE)
    check_integer(entry, 'width', width, 1, MAX_IMAGE_SIDE)
    check_integer(entry, 'num_steps', num_steps, 1, MAX_NUM_STEPS)
    check_integer(entry, 'num_frames', num_frames, 1, MAX_FRAMES)
    # the simulator's rule, before any file is written
    check_number(entry, 'threshold', threshold, 0, strict_minimum=True,
                 float32=True)
    check_seed(seed, entry=entry)
    check_flag(entry, 'progress', progress)
    check_flag(entry, 'wait', wait)
    from ..core.simulation import simulate_spikes  # torch, where it runs
    written = 0
    recipe = dict(height=height, width=width, num_steps=num_steps,
                  num_frames=num_frames, threshold=threshold, seed=seed)
    jobs = [('train', i) for i in range(num_train)] + [
        ('val', num_train + i) for i in range(num_val)]
    with own_folder(out_dir, wait=wait) as owned:
        for split, scene in tqdm(jobs, desc='synthetic scenes',
                                 disable=not progress):
            stem = f'synth_{scene:06d}_000019'
            folder = osp.join(out_dir, 'spike', split, 'synth')
            marker = owned.file(osp.join(folder, f'{stem}_spike.json'))
            files = dict(
                spike=owned.file(osp.join(folder, f'{stem}_spike.spk')),
                label=owned.file(osp.join(
                    out_dir, 'gtFine', split, 'synth',
                    f'{stem}_gtFine_labelTrainIds.png')))
            if is_complete(marker, recipe, files):
                continue
            frames, label = render_street_scene(
                derive_generator(seed, scene), height, width, num_frames)
            spikes, _ = simulate_spikes(
                frames, num_steps, threshold=threshold,
                seed=derive_seed(seed, scene, 'spikes'))
            invalidate(marker)
            records = dict(label=write_png(files['label'], label),
                           spike=save_spikes(files['spike'], spikes))
            write_marker(marker, recipe, records)
            written += 1
    return written
