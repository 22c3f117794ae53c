"""Reading and writing spike streams.

Formats, chosen by the file extension:

``.dat``
    The community's raw format (Spk2ImgNet, WGSE, Spike-Zoo): no header,
    frames concatenated, each ``H*W/8`` bytes; pixel ``k = row*W + col`` is
    bit ``k % 8`` of byte ``k // 8``, least-significant bit first; rows are
    stored bottom-up. Height and width come from the caller or from a side
    file ``<file>.json`` holding ``{"height": H, "width": W}``.
``.spk``
    This package's packed format: a 32-byte little-endian header (magic
    ``WGSESPK1``, format version, ``T``, ``H``, ``W``, 8 reserved bytes)
    followed by ``T`` frames, each ``ceil(H*W/8)`` bytes packed as in
    ``.dat`` but stored upright.
``.npy`` / ``.npz``
    A ``(T, H, W)`` array of 0/1 (``.npz``: key ``spikes``, or its only
    array).

Every reader returns a ``(T, H, W)`` ``uint8`` array of 0/1, reads only the
requested window of frames (memory-mapped), and names the file and the
expected sizes when the file does not fit. Writers write atomically: a
temporary file beside the target, renamed into place when complete.
"""
import contextlib
import json
import os
import os.path as osp
import struct
import tempfile
from typing import BinaryIO, Iterator, Optional, Tuple

import cv2
import numpy as np

from .arguments import Integer, Path, declare
from .limits import MAX_IMAGE_SIDE

__all__ = ['SpikeFileError', 'load_spikes', 'save_spikes', 'spike_shape',
           'centered_window', 'atomic_output', 'write_png', 'to_uint8',
           'SPIKE_EXTENSIONS']

SPIKE_EXTENSIONS = ('.dat', '.spk', '.npy', '.npz')
_MAGIC = b'WGSESPK1'
_VERSION = 1
_HEADER = struct.Struct('<8sIIII8x')  # magic, version, T, H, W, reserved


class SpikeFileError(ValueError):
    """A spike file that cannot be read as asked; names the file."""


@contextlib.contextmanager
def atomic_output(path: str) -> Iterator[BinaryIO]:
    """Open ``path`` for binary writing so that it appears whole or not at all.

    Writes go to a temporary file beside ``path``, renamed over it when the
    block ends without error (with the permissions ``open`` would give);
    on error the temporary file is removed and ``path`` is untouched.
    """
    directory = osp.dirname(osp.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=directory, prefix='.tmp-',
                               suffix=osp.splitext(path)[1])
    try:
        with os.fdopen(fd, 'wb') as f:
            yield f
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600
        os.replace(tmp, path)
    except BaseException:
        if osp.exists(tmp):
            os.remove(tmp)
        raise


def write_png(path: str, image: np.ndarray) -> None:
    """Write an 8-bit ``(H, W)`` (grey, labels) or ``(H, W, 3)`` (BGR, OpenCV's
    order) image as a PNG; the file appears complete or not at all."""
    ok, encoded = cv2.imencode('.png', image)
    if not ok:
        raise OSError(f'{path}: PNG encoding failed')
    with atomic_output(path) as f:
        f.write(encoded.tobytes())


def to_uint8(image: np.ndarray) -> np.ndarray:
    """``(H, W)`` float in [0, 1] -> 8-bit grey, rounded, clipped."""
    return np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)


def _check_binary(path: str, spikes: np.ndarray) -> None:
    if not ((spikes == 0) | (spikes == 1)).all():
        raise SpikeFileError(f'{path}: spikes must hold only 0 and 1')


def _extension(path: str) -> str:
    ext = osp.splitext(path)[1].lower()
    if ext not in SPIKE_EXTENSIONS:
        raise SpikeFileError(
            f'{path}: unknown spike file extension {ext!r}; expected one of '
            f'{SPIKE_EXTENSIONS}')
    return ext


def _frame_bytes(height: int, width: int) -> int:
    return (height * width + 7) // 8


def _dat_geometry(path: str, height: Optional[int],
                  width: Optional[int]) -> Tuple[int, int, int]:
    """``(T, H, W)`` of a ``.dat`` file, checking its size."""
    if height is None or width is None:
        side = path + '.json'
        if not osp.exists(side):
            raise SpikeFileError(
                f'{path}: a .dat file has no header, so height and width are '
                f'needed (arguments, or a side file {side} with '
                f'{{"height": H, "width": W}})')
        try:
            with open(side) as f:
                meta = json.load(f)
            height = int(meta['height']) if height is None else height
            width = int(meta['width']) if width is None else width
        except (ValueError, KeyError, TypeError) as err:
            raise SpikeFileError(
                f'{path}: side file {side} must hold {{"height": H, '
                f'"width": W}} ({err!r})') from err
    if height < 1 or width < 1 or (height * width) % 8:
        raise SpikeFileError(
            f'{path}: .dat frames of {height}x{width} are not a whole number '
            f'of bytes (height*width must be a positive multiple of 8)')
    size = osp.getsize(path)
    frame = height * width // 8
    if size == 0 or size % frame:
        raise SpikeFileError(
            f'{path}: {size} bytes is not a whole number of {height}x{width} '
            f'frames ({frame} bytes each); the file is truncated or the '
            f'height/width are wrong')
    return size // frame, height, width


def _spk_geometry(path: str) -> Tuple[int, int, int]:
    size = osp.getsize(path)
    if size < _HEADER.size:
        raise SpikeFileError(
            f'{path}: {size} bytes is shorter than the {_HEADER.size}-byte '
            f'.spk header')
    with open(path, 'rb') as f:
        magic, version, steps, height, width = _HEADER.unpack(
            f.read(_HEADER.size))
    if magic != _MAGIC or version != _VERSION:
        raise SpikeFileError(
            f'{path}: not a version-{_VERSION} .spk file (header starts '
            f'{magic!r}, version {version})')
    expected = _HEADER.size + steps * _frame_bytes(height, width)
    if size != expected:
        raise SpikeFileError(
            f'{path}: header says T={steps}, H={height}, W={width}, which '
            f'needs {expected} bytes, but the file has {size}; it is '
            f'truncated or corrupted')
    return steps, height, width


def centered_window(path: str, total: int, center: int, length: int) -> int:
    """First frame of the ``length``-frame window centred on frame
    ``center`` of a ``total``-frame stream (frame ``center - length // 2``).

    The package's one window policy: a window that does not fit in the
    stream is an error naming the file and the centre frames that fit,
    never moved silently (a moved window no longer has the annotated frame
    at its centre).
    """
    start = center - length // 2
    if length < 1 or start < 0 or start + length > total:
        first = length // 2
        last = total - length + length // 2
        raise SpikeFileError(
            f'{path}: a {length}-frame window centred on frame {center} does '
            f'not fit in the stream\'s {total} frames; centre frames '
            + (f'{first}..{last} fit' if last >= first else 'none fit'))
    return start


def _window(path: str, total: int, start: int,
            length: Optional[int]) -> Tuple[int, int]:
    length = total - start if length is None else length
    if start < 0 or length < 1 or start + length > total:
        raise SpikeFileError(
            f'{path}: frames [{start}, {start + length}) asked for '
            f'(start={start}, length={length}), but the stream has {total} '
            f'frames')
    return start, length


def _unpack(raw: np.ndarray, length: int, height: int,
            width: int) -> np.ndarray:
    bits = np.unpackbits(raw.reshape(length, -1), axis=1, bitorder='little')
    return bits[:, :height * width].reshape(length, height, width)


def _pack(spikes: np.ndarray) -> np.ndarray:
    steps = spikes.shape[0]
    return np.packbits(spikes.reshape(steps, -1), axis=1, bitorder='little')


#: the frame size a caller gives for a ``.dat`` file
_SIDE = Integer(1, MAX_IMAGE_SIDE, optional=True)


@declare(path=Path(), height=_SIDE, width=_SIDE)
def spike_shape(path: str, height: Optional[int] = None,
                width: Optional[int] = None) -> Tuple[int, int, int]:
    """``(T, H, W)`` of a spike file without reading its frames."""
    path = os.fspath(path)
    ext = _extension(path)
    if not osp.exists(path):
        raise SpikeFileError(f'{path}: no such spike file')
    if ext == '.dat':
        return _dat_geometry(path, height, width)
    if ext == '.spk':
        return _spk_geometry(path)
    return _array(path).shape


def _array(path: str) -> np.ndarray:
    try:
        if path.lower().endswith('.npy'):
            array = np.load(path, mmap_mode='r')
        else:
            with np.load(path) as archive:
                keys = list(archive.keys())
                key = 'spikes' if 'spikes' in keys else (
                    keys[0] if len(keys) == 1 else None)
                if key is None:
                    raise SpikeFileError(
                        f'{path}: .npz holds {keys}; expected a key '
                        f'"spikes" or a single array')
                array = archive[key]
    except SpikeFileError:
        raise
    except Exception as err:  # noqa: BLE001 NumPy's parsers raise many types
        # for bad bytes (ValueError, EOFError, zipfile.BadZipFile, zlib.error,
        # tokenize.TokenError, SyntaxError, ...); nothing is executed
        # (allow_pickle stays False)
        raise SpikeFileError(f'{path}: cannot read the array: '
                             f'{type(err).__name__}: {err}') from err
    if array.ndim != 3:
        raise SpikeFileError(
            f'{path}: expected a (T, H, W) array, got shape {array.shape}')
    return array


@declare(path=Path(), height=_SIDE, width=_SIDE, start=Integer(0),
         length=Integer(1, optional=True))
def load_spikes(path: str, height: Optional[int] = None,
                width: Optional[int] = None, start: int = 0,
                length: Optional[int] = None) -> np.ndarray:
    """Read frames ``[start, start + length)`` of a spike file.

    Args:
        path: a ``.dat``, ``.spk``, ``.npy`` or ``.npz`` file.
        height, width: frame size of a ``.dat`` file (others record it).
        start: first frame.
        length: number of frames; ``None`` reads to the end.

    Returns:
        ``(T, H, W)`` ``uint8`` array of 0/1, upright.
    """
    path = os.fspath(path)
    steps, h, w = spike_shape(path, height, width)
    start, length = _window(path, steps, start, length)
    ext = _extension(path)
    if ext in ('.npy', '.npz'):
        window = np.asarray(_array(path)[start:start + length])
        _check_binary(path, window)
        return window.astype(np.uint8)
    frame = _frame_bytes(h, w)
    offset = 0 if ext == '.dat' else _HEADER.size
    raw = np.memmap(path, dtype=np.uint8, mode='r',
                    offset=offset + start * frame, shape=(length * frame, ))
    spikes = _unpack(np.asarray(raw), length, h, w)
    if ext == '.dat':
        spikes = spikes[:, ::-1]  # rows are stored bottom-up
    return np.ascontiguousarray(spikes)


@declare(path=Path())
def save_spikes(path: str, spikes: np.ndarray) -> None:
    """Write a ``(T, H, W)`` 0/1 array to ``path`` (format from extension).

    The file appears complete or not at all.
    """
    path = os.fspath(path)
    ext = _extension(path)
    spikes = np.asarray(spikes)
    if spikes.ndim != 3 or 0 in spikes.shape:
        raise SpikeFileError(
            f'{path}: expected a non-empty (T, H, W) array, got shape '
            f'{spikes.shape}')
    _check_binary(path, spikes)
    spikes = spikes.astype(np.uint8)
    steps, height, width = spikes.shape
    if ext == '.dat' and (height * width) % 8:
        raise SpikeFileError(
            f'{path}: .dat needs height*width divisible by 8, got '
            f'{height}x{width}')
    with atomic_output(path) as f:
        if ext == '.dat':
            f.write(_pack(spikes[:, ::-1]).tobytes())
        elif ext == '.spk':
            f.write(_HEADER.pack(_MAGIC, _VERSION, steps, height, width))
            f.write(_pack(spikes).tobytes())
        elif ext == '.npy':
            np.save(f, spikes)
        else:
            np.savez_compressed(f, spikes=spikes)
