"""Grey images: the one place an image array or file is given its meaning.

Every image the package reads or measures goes through here, so that each
kind keeps its meaning (1 = white) or is refused with a clear error:

* ``bool``: ``False``/``True`` -> 0/1;
* ``uint8``: ``value / 255``; ``uint16`` (16-bit PNG/TIFF): ``value /
  65535``;
* float: the value itself, which must be finite and in ``[0, 1]``;
* anything else (signed or wider integers, whose white is unknown;
  complex; strings) is refused.

:func:`as_unit_grey` gives an ``(H, W)`` float64 array (the full-reference
measures, 8 bytes per pixel); :func:`as_grey_levels` the image as shown in
8 bits, ``uint8`` (the no-reference measures), converted by blocks of rows
so that it needs 1 byte per pixel plus a fixed
:data:`BLOCK_PIXELS`-sized working set; :func:`read_grey_image` a file
(8 or 16 bits, grey, colour or with alpha; float TIFF in ``[0, 1]``).

Every image file is bounded before it is decoded (:func:`read_image`, the
one reader of image files): its width and height are read from its header
(:func:`image_size`: PNG, JPEG, BMP, GIF, TIFF, WebP, PNM) and checked
against :data:`~wgse_mmseg.core.limits.MAX_IMAGE_SIDE`, a PNG without its
end chunk or a JPEG without its end marker (a truncated file, which
OpenCV would decode half grey with only a warning) is refused, and a file
of another kind, a FIFO or a folder is refused, each naming the file.
:func:`fit_within` scales an image down to a bound, never to 0 pixels.
"""
import os
import struct
from typing import Iterator, Tuple

import numpy as np

from .limits import MAX_IMAGE_SIDE, check_allocation, check_utf8_path
from .output_folder import check_input_file

__all__ = []

#: pixels per block of rows a conversion or a measure works on at once
BLOCK_PIXELS = 1 << 16
#: integer dtypes with a known white
_WHITE = {np.dtype(np.uint8): 255, np.dtype(np.uint16): 65535}


def row_blocks(height: int, width: int) -> Iterator[Tuple[int, int]]:
    """``(first, stop)`` row ranges of about :data:`BLOCK_PIXELS` pixels
    covering ``height`` rows of ``width`` pixels."""
    rows = max(1, BLOCK_PIXELS // max(1, width))
    for first in range(0, height, rows):
        yield first, min(height, first + rows)


def full_scale(dtype, name: str) -> int:
    """The value of white in an image of ``dtype``: 255 (``uint8``),
    65535 (``uint16``), 1 (``bool``, float).

    Raises:
        ValueError: naming ``name``, for any other dtype (its white is not
            known).
    """
    dtype = np.dtype(dtype)
    if dtype in _WHITE:
        return _WHITE[dtype]
    if dtype == np.bool_ or np.issubdtype(dtype, np.floating):
        return 1
    raise ValueError(
        f'{name} must be a bool, uint8 (0-255), uint16 (0-65535) or '
        f'float (0-1) image, got dtype {dtype} (its white is not known: '
        f'scale it to one of these)')


def check_unit_range(values: np.ndarray, name: str) -> None:
    """Refuse float ``values`` that are not finite or not in [0, 1]
    (``ValueError`` naming ``name`` and the range found)."""
    bad = ~np.isfinite(values)
    if bad.any():
        raise ValueError(f'{name}: a float image must lie in [0, 1] (1 = '
                         f'white), found {int(bad.sum())} non-finite '
                         f'value(s)')
    low, high = float(values.min()), float(values.max())
    if low < 0 or high > 1:
        raise ValueError(
            f'{name}: a float image must lie in [0, 1] (1 = white), found '
            f'values in [{low:.6g}, {high:.6g}]; clip or rescale it')


def _checked(image, name: str) -> np.ndarray:
    """``image`` as an ``(H, W)`` array of an accepted kind (not yet
    converted)."""
    array = np.asarray(image)
    if array.ndim != 2 or array.size == 0:
        raise ValueError(f'{name} must be a non-empty (H, W) image, got '
                         f'shape {array.shape}')
    full_scale(array.dtype, name)
    return array


def _unit_block(block: np.ndarray, name: str) -> np.ndarray:
    """A block of rows of a :func:`_checked` image as float64, 1 = white;
    float values are checked to be finite and in [0, 1]."""
    values = block.astype(np.float64)
    if np.issubdtype(block.dtype, np.floating):
        check_unit_range(values, name)
    return values / full_scale(block.dtype, name)


def as_unit_grey(image, name: str = 'image') -> np.ndarray:
    """``image`` as an ``(H, W)`` float64 array in [0, 1], 1 = white.

    Raises ``ValueError`` naming ``name`` for anything but a non-empty
    ``(H, W)`` image of an accepted kind (module docstring).
    """
    return _unit_block(_checked(image, name), name)


def as_grey_levels(image, name: str = 'image') -> np.ndarray:
    """``image`` as shown in 8 bits: ``(H, W)`` ``uint8``, ``round(255 *
    value)`` of :func:`as_unit_grey`'s value (a ``uint8`` image as it is).

    Converted by :func:`row_blocks`: 1 byte per pixel for the result plus
    a working set of about ``24 * BLOCK_PIXELS`` bytes.
    """
    array = _checked(image, name)
    if array.dtype == np.uint8:
        return array
    levels = np.empty(array.shape, np.uint8)
    for first, stop in row_blocks(*array.shape):
        levels[first:stop] = np.round(
            _unit_block(array[first:stop], name) * 255)
    return levels


class ImageFileError(ValueError):
    """An image file that is not read: of an unknown kind, larger than the
    limits, truncated or undecodable; names the file."""


#: bytes of a file's start that hold the headers :func:`image_size` reads
#: (a JPEG's frame header after large metadata segments and a TIFF's
#: directory are found by seeking)
_HEAD_BYTES = 1 << 16


def _jpeg_size(f, path: str) -> Tuple[int, int]:
    """``(width, height)`` from a JPEG's first frame header (SOF)."""
    f.seek(2)
    while True:
        marker = f.read(2)
        while marker[:1] == b'\xff' and marker[1:] == b'\xff':
            marker = marker[1:] + f.read(1)  # fill bytes
        if len(marker) < 2 or marker[0] != 0xff:
            raise ImageFileError(f'{path}: a JPEG without a frame header')
        kind = marker[1]
        if kind in (0xd8, 0x01) or 0xd0 <= kind <= 0xd7:
            continue  # markers without a length
        length = f.read(2)
        if len(length) < 2:
            raise ImageFileError(f'{path}: a truncated JPEG header')
        size = struct.unpack('>H', length)[0]
        if 0xc0 <= kind <= 0xcf and kind not in (0xc4, 0xc8, 0xcc):
            header = f.read(5)
            if len(header) < 5:
                raise ImageFileError(f'{path}: a truncated JPEG header')
            height, width = struct.unpack('>HH', header[1:5])
            return width, height
        if kind == 0xd9 or size < 2:
            raise ImageFileError(f'{path}: a JPEG without a frame header')
        f.seek(size - 2, os.SEEK_CUR)


def _tiff_size(f, head: bytes, path: str) -> Tuple[int, int]:
    """``(width, height)`` from a TIFF's first directory."""
    order = '<' if head[:2] == b'II' else '>'
    (offset, ) = struct.unpack(order + 'I', head[4:8])
    f.seek(offset)
    count = f.read(2)
    if len(count) < 2:
        raise ImageFileError(f'{path}: a TIFF whose first directory is cut '
                             f'short')
    (count, ) = struct.unpack(order + 'H', count)
    entries = f.read(12 * count)
    found = {}
    for index in range(count):
        entry = entries[12 * index:12 * index + 12]
        if len(entry) < 12:
            break
        tag, kind = struct.unpack(order + 'HH', entry[:4])
        value = struct.unpack(order + ('H' if kind == 3 else 'I'),
                              entry[8:10] if kind == 3 else entry[8:12])[0]
        found[tag] = value
    if 256 not in found or 257 not in found:
        raise ImageFileError(f'{path}: a TIFF without its width and height')
    return found[256], found[257]


def _webp_size(head: bytes, path: str) -> Tuple[int, int]:
    chunk = head[12:16]
    if chunk == b'VP8 ' and len(head) >= 30:
        width, height = struct.unpack('<HH', head[26:30])
        return width & 0x3fff, height & 0x3fff
    if chunk == b'VP8L' and len(head) >= 25:
        bits = int.from_bytes(head[21:25], 'little')
        return (bits & 0x3fff) + 1, ((bits >> 14) & 0x3fff) + 1
    if chunk == b'VP8X' and len(head) >= 30:
        return (int.from_bytes(head[24:27], 'little') + 1,
                int.from_bytes(head[27:30], 'little') + 1)
    raise ImageFileError(f'{path}: a WebP file of an unknown layout')


def _pnm_size(head: bytes, path: str) -> Tuple[int, int]:
    words = []
    for line in head[2:512].split(b'\n'):
        words += line.split(b'#')[0].split()
        if len(words) >= 2:
            try:
                return int(words[0]), int(words[1])
            except ValueError:
                break
    raise ImageFileError(f'{path}: a PNM file without its width and height')


def image_size(path: str) -> Tuple[str, int, int]:
    """The kind (``'png'``, ``'jpeg'``, ...), width and height an image
    file's header declares, without decoding it.

    Raises:
        ImageFileError: naming ``path``, for a file of none of the kinds
            (module docstring) or a header cut short.
    """
    with open(path, 'rb') as f:
        head = f.read(_HEAD_BYTES)
        if head[:8] == b'\x89PNG\r\n\x1a\n' and head[12:16] == b'IHDR':
            return ('png', ) + struct.unpack('>II', head[16:24])
        if head[:3] == b'\xff\xd8\xff':
            return ('jpeg', ) + _jpeg_size(f, path)
        if head[:4] in (b'II*\x00', b'MM\x00*') and len(head) >= 8:
            return ('tiff', ) + _tiff_size(f, head, path)
    if head[:2] == b'BM' and len(head) >= 26:
        width, height = struct.unpack('<ii', head[18:26])
        return 'bmp', abs(width), abs(height)
    if head[:6] in (b'GIF87a', b'GIF89a') and len(head) >= 10:
        return ('gif', ) + struct.unpack('<HH', head[6:10])
    if head[:4] == b'RIFF' and head[8:12] == b'WEBP':
        return ('webp', ) + _webp_size(head, path)
    if len(head) > 2 and head[:1] == b'P' and head[1:2] in b'123456':
        return ('pnm', ) + _pnm_size(head, path)
    raise ImageFileError(
        f'{path}: not an image file of a kind read here (PNG, JPEG, BMP, '
        f'GIF, TIFF, WebP, PNM) or its header is cut short')


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


#: ``cv2.IMREAD_UNCHANGED`` and ``cv2.INTER_AREA``, without importing
#: OpenCV where no image is read
IMREAD_UNCHANGED, INTER_AREA = -1, 3


def read_image(path: str, flags: int = IMREAD_UNCHANGED) -> np.ndarray:
    """``cv2.imread(path, flags)`` of a file checked first: a regular file
    (a FIFO would block the reader), of a kind :func:`image_size` reads,
    at most :data:`~wgse_mmseg.core.limits.MAX_IMAGE_SIDE` pixels a side
    by its header and within the allocation limit as a whole
    (:func:`~wgse_mmseg.core.limits.check_allocation`), not truncated;
    noted as an input
    (:func:`~wgse_mmseg.core.output_folder.check_input_file`).

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
            f'(wgse_mmseg.core.limits.MAX_IMAGE_SIDE)')
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


def fit_within(image: np.ndarray, max_side: int,
               interpolation: int = INTER_AREA) -> np.ndarray:
    """``image`` ``(H, W[, C])`` scaled down by one factor so that neither
    side exceeds ``max_side``, each side at least 1 pixel (a 100000x1
    image does not become 0 pixels wide); as it is where it fits."""
    height, width = image.shape[:2]
    scale = max_side / max(height, width)
    if scale >= 1:
        return image
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    import cv2
    return cv2.resize(image, size, interpolation=interpolation)


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
