"""REDS-style views: clips of a camera moving over still images.

What :class:`~wgse_mmseg.datasets.SimulatedSpikeImageDataset` draws its
samples from, usable without OpenMMLab: images read as grey
(:func:`read_grey_image`, :func:`load_images`) and a view moved along a
random smooth trajectory (shift, rotation, zoom) over one of them
(:func:`render_trajectory`), the frames the simulator turns into spikes.
"""
from typing import List, Tuple

import cv2
import numpy as np
import torch

from ..fileio.folder_walk import files_under
from ..core.image_values import fit_within
from ..fileio.images import read_grey_image
from ..limits import check_allocation
from ..core.simulation import trajectory_source_maps

__all__ = []

#: the image files :func:`load_images` reads
IMAGE_EXTENSIONS = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff',
                    '.webp')


def load_images(image_dir: str, max_side: int) -> Tuple[List[str],
                                                        List[np.ndarray]]:
    """Every image under ``image_dir`` (recursively, sorted by path; each
    file once, however many links lead to it, and a tree with links to
    itself walked to its end: :func:`~wgse_mmseg.fileio.folder_walk.
    files_under`), as ``(H, W)`` float32 grey in [0, 1], downscaled to at
    most ``max_side`` pixels per side; returns the paths and the images."""
    paths = files_under(image_dir, IMAGE_EXTENSIONS)
    if not paths:
        raise FileNotFoundError(
            f'{image_dir}: no images ({", ".join(IMAGE_EXTENSIONS)})')
    images = []
    for path in paths:
        images.append(fit_within(read_grey_image(path), max_side))
    return paths, images


def render_trajectory(image: np.ndarray, size: Tuple[int, int],
                      num_steps: int, rng: np.random.Generator,
                      max_speed: float = 0.6, max_rotation: float = 0.002,
                      max_zoom: float = 0.003,
                      scale_range: Tuple[float, float] = (0.7, 2.5)
                      ) -> np.ndarray:
    """A ``num_steps``-frame clip of a camera moving over a still image.

    A view of ``size`` ``(h, w)`` pixels, centred at a random point of
    ``image`` ``(H, W)`` at a random base angle and base scale (source pixels
    per view pixel, log-uniform in ``scale_range``), moves along a random
    trajectory of :func:`~wgse_mmseg.core.simulation.trajectory_source_maps`
    with ``tau = t - num_steps // 2`` steps: speed up to ``max_speed`` view
    px/step, acceleration up to ``max_speed / num_steps``, rotation up to
    ``max_rotation`` rad/step and zoom up to ``max_zoom`` per step, each in a
    random direction. Borders reflect.

    Returns:
        ``(num_steps, h, w)`` float32 frames; frame ``num_steps // 2`` is the
        view at the trajectory's reference point.
    """
    height, width = size
    check_allocation(num_steps * height * width * 4,
                     f'the {num_steps} x {height} x {width} float32 frames '
                     f'of a trajectory', 'num_steps or the crop size')

    def random_vector(magnitude):
        angle = rng.uniform(-np.pi, np.pi)
        return tuple(rng.uniform(0, magnitude) *
                     np.array([np.cos(angle), np.sin(angle)]))

    maps = trajectory_source_maps(
        torch.arange(num_steps, dtype=torch.float64) - num_steps // 2,
        (height, width),
        source_centre=tuple(rng.uniform([0, 0], [image.shape[1] - 1,
                                                 image.shape[0] - 1])),
        base_scale=float(np.exp(rng.uniform(*np.log(scale_range)))),
        base_angle=rng.uniform(-np.pi, np.pi),
        translation=random_vector(max_speed),
        acceleration=random_vector(max_speed / num_steps),
        rotation=rng.uniform(-max_rotation, max_rotation),
        zoom=rng.uniform(-max_zoom, max_zoom)).numpy()
    frames = np.empty((num_steps, height, width), np.float32)
    for step, matrix in enumerate(maps):
        frames[step] = cv2.warpAffine(
            image, matrix, (width, height),
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_REFLECT_101)
    return frames
