"""Reading and writing spike streams, in every format of
:mod:`wgse_mmseg.core.spike_formats`.

The layout of an ``.npy``/``.npz`` array cannot be told from its shape, so
it is never guessed. It comes from what the file records, or else from the
caller's ``layout`` argument:

* an ``.npz`` member ``layout`` holding ``'THW'`` or ``'HWT'``
  (:func:`save_spikes` writes ``'THW'``);
* an ``.npz`` key ``spk``: the Spike-Zoo toolbox's published convention
  (its UHSR recordings), whose readers take it as ``(T, H, W)``, so the key
  itself states the layout;
* a side file ``<file>.json`` holding ``{"layout": "THW"}`` (or
  ``"HWT"``): ``.npy`` has no room for it that NumPy's own reader accepts,
  so :func:`save_spikes` writes one beside every ``.npy``.

Where the file records a layout, a ``layout`` argument must agree with it
(one of the two is wrong about the file: an error naming both). Where it
records none and no ``layout`` is given, the read is an error naming the
file, its shape and how to give the layout. ``.dat`` and ``.spk`` store
frames one after another: their layout is ``'THW'``, and ``'HWT'`` for them
is an error.

Every reader returns a ``(T, H, W)`` ``uint8`` array of 0/1, reads only the
requested window of frames (memory-mapped; an ``.npz`` member inflated
once, only up to the window's end, or, where its frames are interleaved
(``(H, W, T)`` stored in C order, ``(T, H, W)`` in Fortran order), inflated
whole in chunks keeping only the window), and names the file and the
expected sizes when the file does not fit. The sizes a file declares (header,
side file, zip member, ``.npy`` header) are checked against the file and
against :mod:`wgse_mmseg.limits` before anything is allocated. Writers
write atomically: a temporary file beside the target, renamed into place when
complete.

``.npy``/``.npz`` files are read by :mod:`.spike_arrays`.
"""
import json
import os
import os.path as osp
from typing import Callable, Dict, NamedTuple, Optional, Tuple

import numpy as np

from ..argument_checks import (check_integer, check_path, check_read_options,
                               integer_expected, is_integer)
from ..core.spike_formats import (SPK_HEADER, SPK_MAGIC, SPK_VERSION,
                                  SpikeFileError, check_binary,
                                  check_caller_size, check_window, encode_dat,
                                  encode_npy, encode_npz, encode_spk,
                                  frame_bytes, unpack_frames)
from ..errors import excerpt
from ..limits import MAX_IMAGE_SIDE
from .atomic import WrittenFile, write_bytes
from .bounded_reads import load_json_file
from .input_guard import check_input_file
from .spike_arrays import array_layout, array_shape, frame_major, read_array

__all__ = ['SpikeFileError', 'load_spikes', 'save_spikes', 'spike_shape']


def _dat_geometry(path: str, height: Optional[int],
                  width: Optional[int]) -> Tuple[int, int, int]:
    """``(T, H, W)`` of a ``.dat`` file, checking its size."""
    side = path + '.json'
    if osp.exists(side):
        try:
            meta = load_json_file(side, 'side file')
        except (OSError, ValueError) as err:
            raise SpikeFileError(f'{path}: {err}') from err
        if not (isinstance(meta, dict) and
                is_integer(meta.get('height'), 1, MAX_IMAGE_SIDE) and
                is_integer(meta.get('width'), 1, MAX_IMAGE_SIDE)):
            raise SpikeFileError(
                f'{path}: side file {side} must hold {{"height": H, '
                f'"width": W}} with '
                f'{integer_expected(1, MAX_IMAGE_SIDE)}, got {excerpt(meta)}')
        check_caller_size(path, f'its side file {side}',
                          (meta['height'], meta['width']), height, width)
        height, width = meta['height'], meta['width']
    elif height is None or width is None:
        raise SpikeFileError(
            f'{path}: a .dat file has no header, so height and width are '
            f'needed (arguments, or a side file {side} with '
            f'{{"height": H, "width": W}})')
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


def _spk_geometry(path: str, height: Optional[int] = None,
                  width: Optional[int] = None) -> Tuple[int, int, int]:
    """``(T, H, W)`` from a ``.spk`` file's checked header (a caller's
    ``height``/``width`` must agree with it)."""
    size = osp.getsize(path)
    if size < SPK_HEADER.size:
        raise SpikeFileError(
            f'{path}: {size} bytes is shorter than the {SPK_HEADER.size}-byte '
            f'.spk header')
    given = height, width
    with open(path, 'rb') as f:
        magic, version, steps, height, width = SPK_HEADER.unpack(
            f.read(SPK_HEADER.size))
    if magic != SPK_MAGIC or version != SPK_VERSION:
        raise SpikeFileError(
            f'{path}: not a version-{SPK_VERSION} .spk file (header starts '
            f'{magic!r}, version {version})')
    if 0 in (steps, height, width):
        raise SpikeFileError(
            f'{path}: header says T={steps}, H={height}, W={width}; each '
            f'must be >= 1')
    expected = SPK_HEADER.size + steps * frame_bytes(height, width)
    if size != expected:
        raise SpikeFileError(
            f'{path}: header says T={steps}, H={height}, W={width}, which '
            f'needs {expected} bytes, but the file has {size}; it is '
            f'truncated or corrupted')
    check_caller_size(path, 'its header', (height, width), *given)
    return steps, height, width


def _read_packed(path: str, shape: Tuple[int, int, int], start: int,
                 length: Optional[int], offset: int,
                 bottom_up: bool) -> np.ndarray:
    """Frames ``[start, start + length)`` of packed frames (``.dat``,
    ``.spk``) after ``offset`` header bytes, memory-mapped, upright."""
    steps, height, width = shape
    frame = frame_bytes(height, width)
    start, length = check_window(path, steps, start, length, height * width)
    raw = np.memmap(path, dtype=np.uint8, mode='r',
                    offset=offset + start * frame, shape=(length * frame, ))
    spikes = unpack_frames(np.asarray(raw), length, height, width)
    if bottom_up:
        spikes = spikes[:, ::-1]
    return np.ascontiguousarray(spikes)


def _read_dat(path, shape, start, length, layout):
    return _read_packed(path, shape, start, length, 0, bottom_up=True)


def _read_spk(path, shape, start, length, layout):
    return _read_packed(path, shape, start, length, SPK_HEADER.size,
                        bottom_up=False)


class SpikeFormat(NamedTuple):
    """One spike file format: what :func:`spike_shape`, :func:`load_spikes`
    and :func:`save_spikes` do for its extension.

    ``layout(path, layout)``
        the layout (``'THW'``/``'HWT'``) the existing file ``path`` stores
        its frames in, from what it records and the caller's ``layout``
        (or ``None``), or a :class:`SpikeFileError` naming the file where
        they disagree or neither tells (see the module docstring).
    ``shape(path, height, width, layout)``
        ``(T, H, W)`` of the existing file ``path`` stored in ``layout``
        (``layout``'s answer) without reading its frames, every size the
        file declares checked against the file and
        :mod:`~wgse_mmseg.limits` (``height``/``width``: the caller's,
        or ``None``; formats that record their size ignore them).
    ``read(path, shape, start, length, layout)``
        frames ``[start, start + length)`` (``length=None``: to the end)
        of the file ``shape`` and ``layout`` describe, as a
        ``(length, H, W)`` ``uint8`` array of 0/1, the window checked by
        :func:`check_window` and the values checked to be 0/1 where the format
        can hold others.
    ``encode(path, spikes)``
        the file's bytes for a checked, non-empty ``(T, H, W)`` ``uint8``
        array of 0/1; a :class:`SpikeFileError` naming ``path`` for what
        the format cannot hold.
    ``side``
        what :func:`save_spikes` writes to the side file ``<path>.json``
        (JSON values), for a format with no room to record it; ``None``
        for no side file.
    """
    extension: str
    layout: Callable[[str, Optional[str]], str]
    shape: Callable[[str, Optional[int], Optional[int], str],
                    Tuple[int, int, int]]
    read: Callable[[str, Tuple[int, int, int], int, Optional[int], str],
                   np.ndarray]
    encode: Callable[[str, np.ndarray], bytes]
    side: Optional[dict] = None


#: the spike formats, by lower-case extension (see the module docstring)
SPIKE_FORMATS: Dict[str, SpikeFormat] = {fmt.extension: fmt for fmt in (
    SpikeFormat('.dat', frame_major,
                lambda path, height, width, layout: _dat_geometry(
                    path, height, width), _read_dat, encode_dat),
    SpikeFormat('.spk', frame_major,
                lambda path, height, width, layout: _spk_geometry(
                    path, height, width),
                _read_spk, encode_spk),
    SpikeFormat('.npy', array_layout, array_shape, read_array,
                encode_npy, side={'layout': 'THW'}),
    SpikeFormat('.npz', array_layout, array_shape, read_array,
                encode_npz),
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


def _existing(path: str) -> SpikeFormat:
    """:func:`_format` of ``path``, an existing regular spike file (a
    FIFO or device would block or never end), noted as an input
    (:func:`~wgse_mmseg.fileio.input_guard.check_input_file`)."""
    fmt = _format(path)
    check_input_file(path, 'spike file', SpikeFileError)
    return fmt


def _check_reader_arguments(entry: str, path, height, width,
                            layout) -> None:
    """The arguments every reader of a spike file takes, checked."""
    check_path(entry, 'path', path)
    check_read_options(entry, height, width, layout)


def spike_shape(path: str, height: Optional[int] = None,
                width: Optional[int] = None,
                layout: Optional[str] = None) -> Tuple[int, int, int]:
    """``(T, H, W)`` of a spike file without reading its frames
    (arguments as :func:`load_spikes`'s)."""
    _check_reader_arguments('spike_shape', path, height, width, layout)
    path = os.fspath(path)
    fmt = _existing(path)
    return fmt.shape(path, height, width, fmt.layout(path, layout))


def load_spikes(path: str, height: Optional[int] = None,
                width: Optional[int] = None, start: int = 0,
                length: Optional[int] = None,
                layout: Optional[str] = None) -> np.ndarray:
    """Read frames ``[start, start + length)`` of a spike file.

    Args:
        path: a spike file (``.dat``, ``.spk``, ``.npy``, ``.npz``).
        height, width: frame size of a ``.dat`` file without a side
            file; other files record it, and a size given that
            contradicts the record is an error naming both.
        start: first frame.
        length: number of frames; ``None`` reads to the end.
        layout: how an ``.npy``/``.npz`` array that does not record it is
            stored: ``'THW'`` ``(T, H, W)`` or ``'HWT'`` ``(H, W, T)``;
            ``None`` takes the layout the file records (an error naming
            the file where it records none). A layout the file records
            otherwise is an error; ``.dat``/``.spk`` are ``'THW'``.

    Returns:
        ``(T, H, W)`` ``uint8`` array of 0/1, upright, whatever the layout
        on disk.

    Raises:
        SpikeFileError: naming the file, for bad arguments, a file that
            does not fit its declared sizes, a layout that cannot be told
            or contradicts the file, or a window over the read limit (2 GiB,
            docs/security.md).
        ArgumentError: for an argument of the wrong kind.
    """
    _check_reader_arguments('load_spikes', path, height, width, layout)
    check_integer('load_spikes', 'start', start, 0)
    check_integer('load_spikes', 'length', length, 1, optional=True)
    path = os.fspath(path)
    fmt = _existing(path)
    layout = fmt.layout(path, layout)
    shape = fmt.shape(path, height, width, layout)
    return fmt.read(path, shape, start, length, layout)


def save_spikes(path: str, spikes: np.ndarray) -> WrittenFile:
    """Write a ``(T, H, W)`` 0/1 array to ``path`` (format from extension),
    recording its layout ``'THW'`` where the format does not fix it
    (``.npz``: a member ``layout``; ``.npy``: the side file
    ``<path>.json``, written first).

    Each file appears complete or not at all. Returns what was written to
    ``path``, as a named tuple: ``size`` and ``sha256`` of the bytes, from
    memory.
    """
    check_path('save_spikes', 'path', path)
    path = os.fspath(path)
    fmt = _format(path)
    spikes = np.asarray(spikes)
    if spikes.ndim != 3 or 0 in spikes.shape:
        raise SpikeFileError(
            f'{path}: expected a non-empty (T, H, W) array, got shape '
            f'{spikes.shape}')
    check_binary(path, spikes)
    encoded = fmt.encode(path, spikes.astype(np.uint8))
    if fmt.side is not None:
        write_bytes(path + '.json', json.dumps(fmt.side).encode())
    return write_bytes(path, encoded)
