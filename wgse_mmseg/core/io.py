"""Reading and writing spike streams.

Formats, chosen by the file extension, each one entry of
:data:`SPIKE_FORMATS` (:class:`SpikeFormat`: its shape, read and encode
functions):

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
requested window of frames (memory-mapped; an ``.npz`` member inflated
once, only up to the window's end), and names the file and the expected
sizes when the file does not fit. The sizes a file declares (header, side
file, zip member, ``.npy`` header) are checked against the file and against
:mod:`wgse_mmseg.core.limits` before anything is allocated. Writers write atomically: a
temporary file beside the target, renamed into place when complete.
"""
import contextlib
import functools
import hashlib
import io
import math
import os
import os.path as osp
import re
import struct
import tempfile
import zipfile
from typing import (BinaryIO, Callable, Dict, Iterator, List, NamedTuple,
                    Optional, Sequence, Tuple)

import cv2
import numpy as np

from .arguments import Integer, Path, declare
from .limits import (MAX_IMAGE_SIDE, READ_LIMIT_BYTES, cut, excerpt,
                     load_json_file)

__all__ = ['SpikeFileError', 'load_spikes', 'save_spikes', 'spike_shape',
           'centered_window', 'atomic_path', 'atomic_output', 'temporaries_of',
           'WrittenFile', 'write_bytes',
           'write_png', 'to_uint8', 'SpikeFormat', 'SPIKE_FORMATS',
           'SPIKE_EXTENSIONS']

_MAGIC = b'WGSESPK1'
_VERSION = 1
_HEADER = struct.Struct('<8sIIII8x')  # magic, version, T, H, W, reserved


class SpikeFileError(ValueError):
    """A spike file that cannot be read as asked; names the file."""


@contextlib.contextmanager
def atomic_path(path: str) -> Iterator[str]:
    """A temporary path to write ``path``'s content to, so that ``path``
    appears whole or not at all (for writers that take a file name, such
    as OpenCV's ``VideoWriter``).

    The temporary file lies beside ``path``, is named after it,
    ``.tmp-<name>.<random><ext>`` (:func:`temporaries_of`), and is renamed
    over ``path`` when the block ends without error (with the permissions
    ``open`` would give); on error it is removed and ``path`` is untouched.
    A process killed mid-write leaves one that the next run for that
    target can find and remove, without touching the temporaries of other
    processes writing beside it.
    """
    directory = osp.dirname(osp.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=directory,
                               prefix=f'.tmp-{osp.basename(path)}.',
                               suffix=osp.splitext(path)[1])
    os.close(fd)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600
        os.replace(tmp, path)
    except BaseException:
        if osp.exists(tmp):
            os.remove(tmp)
        raise


@contextlib.contextmanager
def atomic_output(path: str) -> Iterator[BinaryIO]:
    """Open ``path`` for binary writing so that it appears whole or not at
    all: the file of :func:`atomic_path`."""
    with atomic_path(path) as tmp, open(tmp, 'wb') as f:
        yield f


def temporaries_of(paths: Sequence[str]) -> List[str]:
    """The temporary files :func:`atomic_output` left beside ``paths``
    (a process killed mid-write), listing each folder once."""
    patterns: Dict[str, list] = {}
    for path in paths:
        directory, name = osp.split(osp.abspath(path))
        patterns.setdefault(directory, []).append(re.compile(
            re.escape(f'.tmp-{name}.') + r'[A-Za-z0-9_]+' +
            re.escape(osp.splitext(name)[1])))
    found = []
    for directory, names in patterns.items():
        if not osp.isdir(directory):
            continue
        for entry in os.listdir(directory):
            if entry.startswith('.tmp-') and any(
                    pattern.fullmatch(entry) for pattern in names):
                found.append(osp.join(directory, entry))
    return sorted(found)


class WrittenFile(NamedTuple):
    """What a writer put in a file: its size in bytes and the SHA-256 (hex)
    of those bytes, computed from memory, not read back from disk."""
    size: int
    sha256: str


def write_bytes(path: str, data: bytes) -> WrittenFile:
    """Write ``data`` to ``path``, appearing complete or not at all
    (:func:`atomic_output`); returns its size and SHA-256."""
    with atomic_output(path) as f:
        f.write(data)
    return WrittenFile(len(data), hashlib.sha256(data).hexdigest())


def write_png(path: str, image: np.ndarray) -> WrittenFile:
    """Write an 8-bit ``(H, W)`` (grey, labels) or ``(H, W, 3)`` (BGR, OpenCV's
    order) image as a PNG; the file appears complete or not at all.
    Returns what was written (:class:`WrittenFile`)."""
    ok, encoded = cv2.imencode('.png', image)
    if not ok:
        raise OSError(f'{path}: PNG encoding failed')
    return write_bytes(path, encoded.tobytes())


def to_uint8(image: np.ndarray) -> np.ndarray:
    """``(H, W)`` float in [0, 1] -> 8-bit grey, rounded, clipped."""
    return np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)


def _check_binary(path: str, spikes: np.ndarray) -> None:
    if not ((spikes == 0) | (spikes == 1)).all():
        raise SpikeFileError(f'{path}: spikes must hold only 0 and 1')


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
            meta = load_json_file(side, 'side file')
        except (OSError, ValueError) as err:
            raise SpikeFileError(f'{path}: {err}') from err
        for name, value in (('height', height), ('width', width)):
            if value is None and not (isinstance(meta, dict) and
                                      _SIDE.accepts(meta.get(name))):
                raise SpikeFileError(
                    f'{path}: side file {side} must hold {{"height": H, '
                    f'"width": W}} with {_SIDE.describe()}, got '
                    f'{excerpt(meta)}')
        height = meta['height'] if height is None else height
        width = meta['width'] if width is None else width
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
    if 0 in (steps, height, width):
        raise SpikeFileError(
            f'{path}: header says T={steps}, H={height}, W={width}; each '
            f'must be >= 1')
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


def _window(path: str, total: int, start: int, length: Optional[int],
            frame_size: int) -> Tuple[int, int]:
    """``(start, length)`` of a window of a ``total``-frame stream, checked
    to fit and, at ``frame_size`` bytes a frame once read, to stay within
    :data:`~wgse_mmseg.core.limits.READ_LIMIT_BYTES`."""
    length = total - start if length is None else length
    if start < 0 or length < 1 or start + length > total:
        raise SpikeFileError(
            f'{path}: frames [{start}, {start + length}) asked for '
            f'(start={start}, length={length}), but the stream has {total} '
            f'frames')
    if length * frame_size > READ_LIMIT_BYTES:
        raise SpikeFileError(
            f'{path}: frames [{start}, {start + length}) of {frame_size} '
            f'bytes each are {length * frame_size} bytes, more than the '
            f'{READ_LIMIT_BYTES}-byte read limit (wgse_mmseg.core.limits.'
            f'READ_LIMIT_BYTES); read a shorter window (start, length)')
    return start, length


def _unpack(raw: np.ndarray, length: int, height: int,
            width: int) -> np.ndarray:
    bits = np.unpackbits(raw.reshape(length, -1), axis=1, bitorder='little')
    return bits[:, :height * width].reshape(length, height, width)


def _pack(spikes: np.ndarray) -> np.ndarray:
    steps = spikes.shape[0]
    return np.packbits(spikes.reshape(steps, -1), axis=1, bitorder='little')


def _npy_layout(path: str, f: BinaryIO,
                size: int) -> Tuple[Tuple[int, int, int], np.dtype, bool]:
    """Shape, dtype and Fortran order of the ``.npy`` data ``f`` holds
    (read from its start, left at the first data byte), checked against
    ``size``, the bytes the data has (the file's, or the zip member's
    declared inflated size)."""
    version = np.lib.format.read_magic(f)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
    elif version == (2, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
    else:
        raise SpikeFileError(
            f'{path}: .npy format version {version[0]}.{version[1]}; '
            f'expected 1.0 or 2.0')
    if dtype.hasobject or dtype.kind not in 'biuf':
        raise SpikeFileError(
            f'{path}: an array of {dtype}; expected booleans or numbers')
    if len(shape) != 3 or 0 in shape:
        raise SpikeFileError(
            f'{path}: expected a non-empty (T, H, W) array, got shape '
            f'{shape}')
    needed = f.tell() + math.prod(shape) * dtype.itemsize
    if needed != size:
        raise SpikeFileError(
            f'{path}: the header says shape {shape} of {dtype}, {needed} '
            f'bytes, but the data has {size}; it is truncated or corrupted')
    return shape, dtype, fortran


def _npz_member(path: str, archive: zipfile.ZipFile) -> zipfile.ZipInfo:
    """The member holding the spikes (``spikes.npy``, or the only member),
    its declared inflated size checked against the read limit."""
    names = archive.namelist()
    name = 'spikes.npy' if 'spikes.npy' in names else (
        names[0] if len(names) == 1 and names[0].endswith('.npy') else None)
    if name is None:
        raise SpikeFileError(
            f'{path}: .npz holds {excerpt([n[:-4] for n in names])}; '
            f'expected a key "spikes" or a single array')
    info = archive.getinfo(name)
    if info.file_size > READ_LIMIT_BYTES:
        raise SpikeFileError(
            f'{path}: member {excerpt(name)} declares {info.file_size} '
            f'inflated bytes, more than the {READ_LIMIT_BYTES}-byte read '
            f'limit (wgse_mmseg.core.limits.READ_LIMIT_BYTES)')
    return info


@contextlib.contextmanager
def _array_file(path: str) -> Iterator[
        Tuple[BinaryIO, Tuple[int, int, int], np.dtype, bool]]:
    """The ``.npy`` data of an ``.npy`` file or ``.npz`` member, open at
    its first data byte, with its checked layout (:func:`_npy_layout`).

    An ``.npz`` member inflates only as far as it is read, never past its
    declared size. Every failure is a :class:`SpikeFileError` naming the
    file; nothing is executed (no pickles).
    """
    try:
        with contextlib.ExitStack() as stack:
            if path.lower().endswith('.npy'):
                f = stack.enter_context(open(path, 'rb'))
                size = osp.getsize(path)
            else:
                archive = stack.enter_context(zipfile.ZipFile(path))
                info = _npz_member(path, archive)
                f = stack.enter_context(archive.open(info))
                size = info.file_size
            layout = _npy_layout(path, f, size)
            yield (f, ) + layout
    except SpikeFileError:
        raise
    except Exception as err:  # noqa: BLE001 zipfile, zlib and NumPy's
        # header parser raise many types for bad bytes (ValueError,
        # EOFError, zipfile.BadZipFile, zlib.error, SyntaxError, ...)
        raise SpikeFileError(f'{path}: cannot read the array: '
                             f'{type(err).__name__}: {cut(str(err))}') \
            from err


def _read_array_window(path: str, start: int,
                       length: Optional[int]) -> np.ndarray:
    """Frames ``[start, start + length)`` of an ``.npy``/``.npz`` array,
    in its own dtype (``.npy``: memory-mapped; ``.npz``:
    :func:`_inflated_window`)."""
    if path.lower().endswith('.npz'):
        stat = os.stat(path)
        return _inflated_window(
            path, (stat.st_ino, stat.st_size, stat.st_mtime_ns), start,
            length)
    with _array_file(path) as (f, shape, dtype, fortran):
        start, length = _window(path, shape[0], start, length,
                                math.prod(shape[1:]) * dtype.itemsize)
        array = np.memmap(path, dtype=dtype, mode='r', offset=f.tell(),
                          shape=shape, order='F' if fortran else 'C')
        return np.asarray(array[start:start + length])


@functools.lru_cache(maxsize=1)
def _inflated_window(path: str, identity: Tuple[int, int, int], start: int,
                     length: Optional[int]) -> np.ndarray:
    """Frames ``[start, start + length)`` of an ``.npz`` member, read-only.

    The member inflates once, in chunks, up to the window's end (all of it
    when stored in Fortran order), keeping only the window; the last
    window read is kept, so reading it again (the shape, then the frames,
    of one sample) inflates nothing. ``identity`` (inode, size, mtime) makes
    a changed file a new key.
    """
    with _array_file(path) as (f, shape, dtype, fortran):
        steps, height, width = shape
        frame = height * width * dtype.itemsize
        start, length = _window(path, steps, start, length, frame)
        if fortran:
            array = np.frombuffer(f.read(steps * frame), dtype).reshape(
                shape, order='F')[start:start + length].copy()
        else:
            f.seek(f.tell() + start * frame)  # inflates and drops, in chunks
            data = f.read(length * frame)
            if len(data) != length * frame:
                raise SpikeFileError(f'{path}: the array data is truncated')
            array = np.frombuffer(data, dtype).reshape(length, height, width)
    array.setflags(write=False)
    return array


#: the frame size a caller gives for a ``.dat`` file
_SIDE = Integer(1, MAX_IMAGE_SIDE, optional=True)


def _read_packed(path: str, shape: Tuple[int, int, int], start: int,
                 length: Optional[int], offset: int,
                 bottom_up: bool) -> np.ndarray:
    """Frames ``[start, start + length)`` of packed frames (``.dat``,
    ``.spk``) after ``offset`` header bytes, memory-mapped, upright."""
    steps, height, width = shape
    frame = _frame_bytes(height, width)
    start, length = _window(path, steps, start, length, height * width)
    raw = np.memmap(path, dtype=np.uint8, mode='r',
                    offset=offset + start * frame, shape=(length * frame, ))
    spikes = _unpack(np.asarray(raw), length, height, width)
    if bottom_up:
        spikes = spikes[:, ::-1]
    return np.ascontiguousarray(spikes)


def _read_dat(path, shape, start, length):
    return _read_packed(path, shape, start, length, 0, bottom_up=True)


def _read_spk(path, shape, start, length):
    return _read_packed(path, shape, start, length, _HEADER.size,
                        bottom_up=False)


def _array_shape(path: str, height: Optional[int],
                 width: Optional[int]) -> Tuple[int, int, int]:
    """``(T, H, W)`` an ``.npy``/``.npz`` header declares, checked (the
    array records its size: ``height``/``width`` are not used)."""
    with _array_file(path) as (_, shape, _, _):
        return shape


def _read_array(path, shape, start, length):
    window = _read_array_window(path, start, length)
    _check_binary(path, window)
    return window.astype(np.uint8)


def _encode_dat(path: str, spikes: np.ndarray) -> bytes:
    height, width = spikes.shape[1:]
    if (height * width) % 8:
        raise SpikeFileError(
            f'{path}: .dat needs height*width divisible by 8, got '
            f'{height}x{width}')
    return _pack(spikes[:, ::-1]).tobytes()


def _encode_spk(path: str, spikes: np.ndarray) -> bytes:
    return _HEADER.pack(_MAGIC, _VERSION, *spikes.shape) + \
        _pack(spikes).tobytes()


def _encode_npy(path: str, spikes: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, spikes)
    return buffer.getvalue()


def _encode_npz(path: str, spikes: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.savez_compressed(buffer, spikes=spikes)
    return buffer.getvalue()


class SpikeFormat(NamedTuple):
    """One spike file format: what :func:`spike_shape`, :func:`load_spikes`
    and :func:`save_spikes` do for its extension.

    ``shape(path, height, width)``
        ``(T, H, W)`` of the existing file ``path`` without reading its
        frames, every size the file declares checked against the file and
        :mod:`~wgse_mmseg.core.limits` (``height``/``width``: the caller's,
        or ``None``; formats that record their size ignore them).
    ``read(path, shape, start, length)``
        frames ``[start, start + length)`` (``length=None``: to the end)
        of the file ``shape`` describes, as a ``(length, H, W)`` ``uint8``
        array of 0/1, the window checked by :func:`_window` and the values
        checked to be 0/1 where the format can hold others.
    ``encode(path, spikes)``
        the file's bytes for a checked, non-empty ``(T, H, W)`` ``uint8``
        array of 0/1; a :class:`SpikeFileError` naming ``path`` for what
        the format cannot hold.
    """
    extension: str
    shape: Callable[[str, Optional[int], Optional[int]],
                    Tuple[int, int, int]]
    read: Callable[[str, Tuple[int, int, int], int, Optional[int]],
                   np.ndarray]
    encode: Callable[[str, np.ndarray], bytes]


#: the spike formats, by lower-case extension (see the module docstring)
SPIKE_FORMATS: Dict[str, SpikeFormat] = {fmt.extension: fmt for fmt in (
    SpikeFormat('.dat', _dat_geometry, _read_dat, _encode_dat),
    SpikeFormat('.spk', lambda path, height, width: _spk_geometry(path),
                _read_spk, _encode_spk),
    SpikeFormat('.npy', _array_shape, _read_array, _encode_npy),
    SpikeFormat('.npz', _array_shape, _read_array, _encode_npz),
)}
#: the extensions of :data:`SPIKE_FORMATS`
SPIKE_EXTENSIONS = tuple(SPIKE_FORMATS)


def _format(path: str) -> SpikeFormat:
    """The entry of :data:`SPIKE_FORMATS` for ``path``'s extension."""
    ext = osp.splitext(path)[1].lower()
    if ext not in SPIKE_FORMATS:
        raise SpikeFileError(
            f'{path}: unknown spike file extension {ext!r}; expected one of '
            f'{SPIKE_EXTENSIONS}')
    return SPIKE_FORMATS[ext]


@declare(path=Path(), height=_SIDE, width=_SIDE)
def spike_shape(path: str, height: Optional[int] = None,
                width: Optional[int] = None) -> Tuple[int, int, int]:
    """``(T, H, W)`` of a spike file without reading its frames."""
    path = os.fspath(path)
    fmt = _format(path)
    if not osp.exists(path):
        raise SpikeFileError(f'{path}: no such spike file')
    return fmt.shape(path, height, width)


@declare(path=Path(), height=_SIDE, width=_SIDE, start=Integer(0),
         length=Integer(1, optional=True))
def load_spikes(path: str, height: Optional[int] = None,
                width: Optional[int] = None, start: int = 0,
                length: Optional[int] = None) -> np.ndarray:
    """Read frames ``[start, start + length)`` of a spike file.

    Args:
        path: a file of one of :data:`SPIKE_FORMATS` (``.dat``, ``.spk``,
            ``.npy``, ``.npz``).
        height, width: frame size of a ``.dat`` file (others record it).
        start: first frame.
        length: number of frames; ``None`` reads to the end.

    Returns:
        ``(T, H, W)`` ``uint8`` array of 0/1, upright.

    Raises:
        SpikeFileError: naming the file, for bad arguments, a file that
            does not fit its declared sizes, or a window over
            :data:`~wgse_mmseg.core.limits.READ_LIMIT_BYTES`.
    """
    path = os.fspath(path)
    shape = spike_shape(path, height, width)
    return _format(path).read(path, shape, start, length)


@declare(path=Path())
def save_spikes(path: str, spikes: np.ndarray) -> WrittenFile:
    """Write a ``(T, H, W)`` 0/1 array to ``path`` (format from extension).

    The file appears complete or not at all. Returns what was written
    (:class:`WrittenFile`: size and SHA-256 of the bytes, from memory).
    """
    path = os.fspath(path)
    fmt = _format(path)
    spikes = np.asarray(spikes)
    if spikes.ndim != 3 or 0 in spikes.shape:
        raise SpikeFileError(
            f'{path}: expected a non-empty (T, H, W) array, got shape '
            f'{spikes.shape}')
    _check_binary(path, spikes)
    return write_bytes(path, fmt.encode(path, spikes.astype(np.uint8)))
