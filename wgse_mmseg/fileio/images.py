"""Image files: the one reader of them, bounded before it decodes.

Every image file is bounded before it is decoded (:func:`read_image`): its
kind, width and height are read from its header by Pillow
(:func:`image_size`: PNG, JPEG, BMP, GIF, TIFF, WebP, PNM) and checked
against :data:`~wgse_mmseg.limits.MAX_IMAGE_SIDE` and the allocation
limit; a PNG without its end chunk or a JPEG without its end marker (a
truncated file, which OpenCV would decode half grey with only a warning)
is refused, and a file of another kind, a FIFO or a folder is refused, each
naming the file. OpenCV decodes it. :func:`write_png` writes one
atomically. What the pixel values mean is :mod:`wgse_mmseg.core.image_values`'.
"""
import os
from typing import Tuple

import numpy as np

from ..core.image_values import as_unit_grey
from ..errors import WgseError
from ..limits import MAX_IMAGE_SIDE, check_allocation
from .atomic import WrittenFile, write_bytes
from .bounded_reads import check_utf8_path
from .input_guard import check_input_file

__all__ = []

#: ``cv2.IMREAD_UNCHANGED``, without importing OpenCV where no image is read
IMREAD_UNCHANGED = -1


class ImageFileError(WgseError, ValueError):
    """An image file that is not read: of an unknown kind, larger than the
    limits, truncated or undecodable; names the file."""


#: Pillow's format names -> the kinds read here (those OpenCV decodes)
_KINDS = {'PNG': 'png', 'JPEG': 'jpeg', 'BMP': 'bmp', 'GIF': 'gif',
          'TIFF': 'tiff', 'WEBP': 'webp', 'PPM': 'pnm'}


def image_size(path: str) -> Tuple[str, int, int]:
    """The kind (``'png'``, ``'jpeg'``, ...), width and height an image
    file's header declares, read by Pillow without decoding the pixels.

    Raises:
        ImageFileError: naming ``path``, for a file of none of the kinds
            (module docstring), a header cut short, or more pixels than
            Pillow's decompression-bomb limit (``PIL.Image.MAX_IMAGE_PIXELS``,
            twice over).
    """
    from PIL import Image, UnidentifiedImageError
    try:
        with Image.open(path) as image:
            kind = _KINDS.get(image.format)
            width, height = image.size
    except Image.DecompressionBombError as err:
        raise ImageFileError(
            f'{path}: its header declares more pixels than Pillow reads '
            f'safely ({err})') from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError):
        kind = None
    if kind is None:
        raise ImageFileError(
            f'{path}: not an image file of a kind read here (PNG, JPEG, BMP, '
            f'GIF, TIFF, WebP, PNM) or its header is cut short')
    return kind, width, height


def _truncated(path: str, kind: str) -> bool:
    """Whether a PNG lacks its end chunk or a JPEG its end marker."""
    if kind not in ('png', 'jpeg'):
        return False
    with open(path, 'rb') as f:
        f.seek(max(0, os.fstat(f.fileno()).st_size - 4096))
        tail = f.read()
    if kind == 'png':
        return b'IEND\xaeB`\x82' not in tail
    return b'\xff\xd9' not in tail


def read_image(path: str, flags: int = IMREAD_UNCHANGED) -> np.ndarray:
    """``cv2.imread(path, flags)`` of a file checked first: a regular file
    (a FIFO would block the reader), of a kind :func:`image_size` reads,
    at most :data:`~wgse_mmseg.limits.MAX_IMAGE_SIDE` pixels a side
    by its header and within the allocation limit as a whole
    (:func:`~wgse_mmseg.limits.check_allocation`), not truncated;
    noted as an input
    (:func:`~wgse_mmseg.fileio.input_guard.check_input_file`).

    Raises:
        FileNotFoundError: nothing at ``path``.
        ValueError: a path that is not UTF-8 (OpenCV cannot open it).
        ImageFileError: naming ``path`` and what is wrong with it.
    """
    check_utf8_path(path, 'OpenCV')
    check_input_file(path, 'image file', ImageFileError, FileNotFoundError)
    kind, width, height = image_size(path)
    if not (1 <= width <= MAX_IMAGE_SIDE and 1 <= height <= MAX_IMAGE_SIDE):
        raise ImageFileError(
            f'{path}: its header declares a {width}x{height} image; images '
            f'of 1 to {MAX_IMAGE_SIDE} pixels a side are read '
            f'(wgse_mmseg.limits.MAX_IMAGE_SIDE)')
    if _truncated(path, kind):
        raise ImageFileError(f'{path}: a truncated {kind.upper()} (its end '
                             f'is missing); the file is incomplete')
    # as a whole, before decoding: at most 4 channels of 16 bits
    check_allocation(width * height * 4 * 2,
                     f'{path}: decoding its {width}x{height} image',
                     'the image size')
    import cv2
    image = cv2.imread(path, flags)
    if image is None:
        raise ImageFileError(f'{path}: a {kind.upper()} that OpenCV cannot '
                             f'decode')
    return image


def read_grey_image(path: str) -> np.ndarray:
    """An image file as ``(H, W)`` float32 grey in [0, 1]: 8-bit and 16-bit
    files at their full depth (colour -> luma, alpha dropped), float files
    (TIFF) when their values are in [0, 1].

    Raises:
        FileNotFoundError: naming ``path``, for no readable image there.
        ValueError: naming ``path``, for an image of another kind (module
            docstring).
    """
    import cv2

    # full depth, grey or colour as stored, EXIF orientation applied
    image = read_image(path, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
    if image.ndim == 3:
        if image.dtype == np.float64:  # cvtColor takes float32
            image = image.astype(np.float32)
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return as_unit_grey(image, path).astype(np.float32)


def write_png(path: str, image: np.ndarray) -> WrittenFile:
    """Write an 8-bit ``(H, W)`` (grey, labels) or ``(H, W, 3)`` (BGR, OpenCV's
    order) image as a PNG; the file appears complete or not at all.
    Returns what was written (:class:`WrittenFile`)."""
    import cv2  # where used: the spike readers need no OpenCV
    ok, encoded = cv2.imencode('.png', image)
    if not ok:
        raise OSError(f'{path}: PNG encoding failed')
    return write_bytes(path, encoded.tobytes())


def to_uint8(image: np.ndarray) -> np.ndarray:
    """``(H, W)`` float in [0, 1] -> 8-bit grey, rounded, clipped."""
    return np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)
