"""Cityscapes as it lies on disk: its splits, its labels and their train
ids (:data:`CITYSCAPES_LABELS`, :func:`labelids_to_trainids`), and the
samples of a root with their annotated frame and, where the sequence is
there, the frames around it (:func:`find_samples`). The conversion
(:mod:`.cityscapes_conversion`) reads them.
"""
import os.path as osp
import re
from dataclasses import dataclass
from typing import List, Sequence, Tuple

import numpy as np

from ..fileio.folder_walk import files_under

CITYSCAPES_FPS = 17.0  # leftImg8bit_sequence frame rate


ANNOTATED_INDEX = 19  # the annotated frame is the 20th of a 30-frame snippet


SNIPPET_LENGTH = 30


#: the splits of a Cityscapes root
CITYSCAPES_SPLITS = ('train', 'val', 'test')


IGNORE_INDEX = 255


# Cityscapes' class definitions (cityscapesscripts' labels.py): label id,
# name, train id. Train id 255 (and -1, the licence plate) is ignored.
CITYSCAPES_LABELS: Tuple[Tuple[int, str, int], ...] = (
    (0, 'unlabeled', 255), (1, 'ego vehicle', 255),
    (2, 'rectification border', 255), (3, 'out of roi', 255),
    (4, 'static', 255), (5, 'dynamic', 255), (6, 'ground', 255),
    (7, 'road', 0), (8, 'sidewalk', 1), (9, 'parking', 255),
    (10, 'rail track', 255), (11, 'building', 2), (12, 'wall', 3),
    (13, 'fence', 4), (14, 'guard rail', 255), (15, 'bridge', 255),
    (16, 'tunnel', 255), (17, 'pole', 5), (18, 'polegroup', 255),
    (19, 'traffic light', 6), (20, 'traffic sign', 7),
    (21, 'vegetation', 8), (22, 'terrain', 9), (23, 'sky', 10),
    (24, 'person', 11), (25, 'rider', 12), (26, 'car', 13),
    (27, 'truck', 14), (28, 'bus', 15), (29, 'caravan', 255),
    (30, 'trailer', 255), (31, 'train', 16), (32, 'motorcycle', 17),
    (33, 'bicycle', 18), (-1, 'license plate', -1))


def _lookup_tables() -> Tuple[np.ndarray, np.ndarray]:
    """256-entry ``uint8`` label id -> train id table, and which ids exist.

    A ``uint8`` label image stores id -1 as 255.
    """
    table = np.full(256, IGNORE_INDEX, np.uint8)
    known = np.zeros(256, bool)
    for label_id, _, train_id in CITYSCAPES_LABELS:
        table[label_id % 256] = train_id if train_id >= 0 else IGNORE_INDEX
        known[label_id % 256] = True
    return table, known


LABEL_ID_TO_TRAIN_ID, _KNOWN_LABEL_IDS = _lookup_tables()
#: whether a value of a train-id label is a train id (0-18) or ignored
KNOWN_TRAIN_IDS = np.zeros(256, bool)
KNOWN_TRAIN_IDS[[*range(19), IGNORE_INDEX]] = True


_STEM = re.compile(r'^(?P<city>.+)_(?P<seq>\d+)_(?P<frame>\d+)$')


_IMAGE_SUFFIX = '_leftImg8bit.png'


_LABEL_SUFFIXES = {'labelTrainIds': '_gtFine_labelTrainIds.png',
                   'labelIds': '_gtFine_labelIds.png'}


@dataclass(frozen=True)
class CityscapesSample:
    """One annotated Cityscapes frame and the files that make its sample.

    ``label_kind`` is ``'labelTrainIds'`` (copied) or ``'labelIds'``
    (mapped to train ids). ``sequence`` lists the frames
    ``frame - K .. frame + K``: ``image`` in the middle, its neighbours from
    ``leftImg8bit_sequence``; it is empty for the static model.
    """
    split: str
    city: str
    stem: str
    image: str
    label: str
    label_kind: str
    sequence: Tuple[str, ...] = ()


def _require_dir(path: str, what: str) -> None:
    if not osp.isdir(path):
        raise FileNotFoundError(f'{path}: missing; expected {what}')


def _sequence_frames(root: str, split: str, city: str, image: str,
                     frames_around: int) -> Tuple[str, ...]:
    """Frames ``frame - K .. frame + K`` of ``image``'s snippet.

    The annotated frame is ``image`` itself; its neighbours come from
    ``leftImg8bit_sequence``. Empty when ``K = 0`` or no neighbour exists.
    """
    if frames_around == 0:
        return ()
    match = _STEM.match(osp.basename(image)[:-len(_IMAGE_SUFFIX)])
    frame, digits = int(match['frame']), len(match['frame'])
    paths = [
        osp.join(root, 'leftImg8bit_sequence', split, city,
                 f'{match["city"]}_{match["seq"]}_'
                 f'{frame + offset:0{digits}d}{_IMAGE_SUFFIX}')
        for offset in range(-frames_around, frames_around + 1)]
    paths[frames_around] = image
    missing = [path for path in paths if not osp.exists(path)]
    if len(missing) == 2 * frames_around:
        return ()
    if missing:
        raise FileNotFoundError(
            f'{missing[0]}: missing, but other frames of its snippet are in '
            f'leftImg8bit_sequence ({len(missing)} of the {2 * frames_around}'
            f' frames around {image} missing); complete the sequence or '
            f'pass frames_around=0 for the static model')
    return tuple(paths)


def find_samples(root: str, splits: Sequence[str] = ('train', 'val'),
                 frames_around: int = 1) -> List[CityscapesSample]:
    """Every annotated frame of ``splits`` under the Cityscapes ``root``.

    Raises ``FileNotFoundError`` naming the path for a missing
    ``leftImg8bit`` or ``gtFine`` split, an annotated frame with no label,
    or a sequence snippet with some of its frames missing.
    """
    samples = []
    for split in splits:
        image_dir = osp.join(root, 'leftImg8bit', split)
        _require_dir(image_dir, f'Cityscapes images leftImg8bit/{split}/'
                     f'<city>/*{_IMAGE_SUFFIX}')
        _require_dir(osp.join(root, 'gtFine', split),
                     f'Cityscapes labels gtFine/{split}/<city>/'
                     f'*_gtFine_labelIds.png')
        images = files_under(image_dir, (_IMAGE_SUFFIX, ), depth=2)
        if not images:
            raise FileNotFoundError(
                f'{image_dir}: holds no <city>/*{_IMAGE_SUFFIX} images')
        for image in images:
            city = osp.basename(osp.dirname(image))
            stem = osp.basename(image)[:-len(_IMAGE_SUFFIX)]
            if not _STEM.match(stem):
                raise ValueError(
                    f'{image}: not a Cityscapes name '
                    f'<city>_<seq>_<frame>{_IMAGE_SUFFIX}')
            labels = {kind: osp.join(root, 'gtFine', split, city,
                                     stem + suffix)
                      for kind, suffix in _LABEL_SUFFIXES.items()}
            kind = next((k for k, p in labels.items() if osp.exists(p)), None)
            if kind is None:
                raise FileNotFoundError(
                    f'{image}: annotated frame has no label; expected '
                    f'{labels["labelTrainIds"]} or {labels["labelIds"]}')
            samples.append(CityscapesSample(
                split, city, stem, image, labels[kind], kind,
                _sequence_frames(root, split, city, image, frames_around)))
    return samples


def labelids_to_trainids(label: np.ndarray, source: str = '<label>'
                         ) -> np.ndarray:
    """Map an ``(H, W)`` ``uint8`` Cityscapes label-id map to train ids.

    Raises ``ValueError`` naming ``source`` for a value that is no
    Cityscapes label id.
    """
    unknown = ~_KNOWN_LABEL_IDS[label]
    if unknown.any():
        raise ValueError(
            f'{source}: values {sorted(set(label[unknown].tolist()))[:10]} '
            f'are not Cityscapes label ids (0..33, 255 for -1)')
    return LABEL_ID_TO_TRAIN_ID[label]


def resize_nearest(label: np.ndarray, height: int, width: int) -> np.ndarray:
    """Nearest-neighbour resize of an ``(H, W)`` map to ``(height, width)``.

    Output pixel ``(i, j)`` is input pixel
    ``(i * H // height, j * W // width)``: OpenCV's ``INTER_NEAREST`` (and
    mmcv's ``'nearest'``) convention, computed exactly. Values are copied,
    never blended.
    """
    rows = np.arange(height) * label.shape[0] // height
    cols = np.arange(width) * label.shape[1] // width
    return label[rows[:, None], cols]
