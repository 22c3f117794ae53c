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
    A 3-D array of 0/1 (``.npz``: key ``spikes``, Spike-Zoo's ``spk``, or
    its only array) stored in either *layout*
    (:data:`~wgse_mmseg.core.arguments.LAYOUT`): ``'THW'``, frames first,
    ``(T, H, W)``; or ``'HWT'``, frames last, ``(H, W, T)``, as some
    simulators and viewers store them.

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
against :mod:`wgse_mmseg.core.limits` before anything is allocated. Writers
write atomically: a temporary file beside the target, renamed into place when
complete.
"""
import contextlib
import errno
import functools
import hashlib
import io
import json
import math
import os
import os.path as osp
import re
import secrets
import shutil
import struct
import tempfile
import zipfile
from typing import (BinaryIO, Callable, Dict, Iterator, List, NamedTuple,
                    Optional, Sequence, Tuple)

import numpy as np

from .arguments import LAYOUT, Integer, Path, declare
from .limits import (MAX_IMAGE_SIDE, READ_LIMIT_BYTES, cut, excerpt,
                     load_json_file)
from .output_folder import (check_input_file, check_output,
                            check_output_kind, note_written)

__all__ = ['SpikeFileError', 'load_spikes', 'save_spikes', 'spike_shape']

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
    over ``path`` when the block ends without error; on any error it is
    removed and ``path`` is untouched. It is created with the permissions
    ``open`` would give (mode ``0o666`` less the umask, applied by the
    kernel: no process-wide setting is read or changed), exclusively, never
    through a link. A process killed mid-write leaves one that the next run
    for that target can find and remove, without touching the temporaries
    of other processes writing beside it. A ``path`` that is an input of
    this process (:func:`~wgse_mmseg.core.output_folder.check_output`) is
    refused before anything is written, and again before the rename. A
    file written inside a folder the package holds is recorded in its
    manifest (:func:`~wgse_mmseg.core.output_folder.note_written`).

    Where a FIFO or a character device lies at ``path`` (``/dev/null``, a
    shell's ``>(cat)``), the temporary file is made in the system's
    temporary folder and, once whole, its bytes are written through to
    ``path``, which is never replaced; a FIFO no process reads is an
    ``OSError`` naming it, not a wait. A socket, a block device or a
    folder at ``path`` is refused before anything is written
    (:func:`~wgse_mmseg.core.output_folder.check_output_kind`).

    An ``OSError`` that names no file (``No space left on device``,
    ``File too large``, ``Read-only file system`` while writing) is raised
    again naming ``path``, of the same ``OSError`` subclass.
    """
    check_output(path)
    streamed = check_output_kind(path) is not None
    directory = (tempfile.gettempdir() if streamed else
                 osp.dirname(osp.abspath(path)))
    try:
        os.makedirs(directory, exist_ok=True)
        tmp = _create_temporary(directory, osp.basename(path),
                                osp.splitext(path)[1])
    except OSError as err:
        raise _naming(path, err) from err
    try:
        yield tmp
        check_output(path)
        if streamed:
            _write_through(tmp, path)
        else:
            os.replace(tmp, path)
            note_written(path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        if isinstance(err, OSError) and err.filename is None:
            raise _naming(path, err) from err
        raise
    finally:
        if streamed:
            with contextlib.suppress(OSError):
                os.remove(tmp)


def _naming(path: str, err: OSError) -> OSError:
    """``err``, an error of writing ``path``, as one that names it: the
    same errno, so the same ``OSError`` subclass."""
    if err.filename is not None or path in str(err.strerror):
        return err
    return OSError(err.errno, f'{path}: cannot be written: '
                   f'{err.strerror or err}')


def _write_through(tmp: str, path: str) -> None:
    """Write the bytes of the file ``tmp`` into ``path``, a FIFO or a
    character device, opened without creating or truncating anything."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError as err:
        if err.errno == errno.ENXIO:
            raise OSError(err.errno, f'{path}: a FIFO that no process '
                          f'reads; start its reader first') from err
        raise
    try:
        os.set_blocking(fd, True)
        with open(tmp, 'rb') as source, os.fdopen(fd, 'wb',
                                                  closefd=False) as out:
            shutil.copyfileobj(source, out)
    finally:
        os.close(fd)


def _create_temporary(directory: str, name: str, suffix: str) -> str:
    """Create, empty, the temporary file ``.tmp-<name>.<random><suffix>``
    in ``directory`` and return its path: ``O_EXCL`` (a new file, never an
    existing one or a link's target), mode ``0o666`` less the umask."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, 'O_NOFOLLOW',
                                                           0)
    while True:
        tmp = osp.join(directory,
                       f'.tmp-{name}.{secrets.token_hex(6)}{suffix}')
        try:
            os.close(os.open(tmp, flags, 0o666))
            return tmp
        except FileExistsError:
            continue


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
    import cv2  # where used: the spike readers need no OpenCV
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


def _check_caller_size(path: str, record: str, recorded: Tuple[int, int],
                       height: Optional[int], width: Optional[int]) -> None:
    """Refuse a caller's ``height``/``width`` (``None``: not given) that
    contradict the ``(H, W)`` that ``path``'s own ``record`` (its header,
    array shape or side file) holds, naming both: reading the bytes as
    another size would give other frames, not an error."""
    given = (height, width)
    if any(value is not None and value != own
           for value, own in zip(given, recorded)):
        raise SpikeFileError(
            f'{path}: height/width {height}x{width} given, but {record} '
            f'says {recorded[0]}x{recorded[1]}; give the file\'s size or '
            f'none')


def _dat_geometry(path: str, height: Optional[int],
                  width: Optional[int]) -> Tuple[int, int, int]:
    """``(T, H, W)`` of a ``.dat`` file, checking its size."""
    side = path + '.json'
    if osp.exists(side):
        try:
            meta = load_json_file(side, 'side file')
        except (OSError, ValueError) as err:
            raise SpikeFileError(f'{path}: {err}') from err
        if not (isinstance(meta, dict) and _SIDE.accepts(meta.get('height'))
                and _SIDE.accepts(meta.get('width'))):
            raise SpikeFileError(
                f'{path}: side file {side} must hold {{"height": H, '
                f'"width": W}} with {_SIDE.describe()}, got '
                f'{excerpt(meta)}')
        _check_caller_size(path, f'its side file {side}',
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
    if size < _HEADER.size:
        raise SpikeFileError(
            f'{path}: {size} bytes is shorter than the {_HEADER.size}-byte '
            f'.spk header')
    given = height, width
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
    _check_caller_size(path, 'its header', (height, width), *given)
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
            + (f'{first}..{last} fit' if last >= first else
               f'none fit: the longest window it holds is {total} frames'))
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


def _npy_header(path: str, f: BinaryIO,
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
            f'{path}: expected a non-empty (T, H, W) array (or (H, W, T), '
            f'layout HWT), got shape {shape}')
    needed = f.tell() + math.prod(shape) * dtype.itemsize
    if needed != size:
        raise SpikeFileError(
            f'{path}: the header says shape {shape} of {dtype}, {needed} '
            f'bytes, but the data has {size}; it is truncated or corrupted')
    return shape, dtype, fortran


#: the ``.npz`` keys that hold spikes, in order of preference: this
#: package's, then the Spike-Zoo toolbox's (whose layout is ``'THW'``)
_NPZ_KEYS = ('spikes', 'spk')
#: the ``.npz`` key recording the array's layout
_NPZ_LAYOUT_KEY = 'layout'


def _npz_member(path: str, archive: zipfile.ZipFile) -> zipfile.ZipInfo:
    """The member holding the spikes (``spikes.npy``, ``spk.npy``, or the
    only array besides a ``layout``), its declared inflated size checked
    against the read limit."""
    names = archive.namelist()
    arrays = [n for n in names if n != f'{_NPZ_LAYOUT_KEY}.npy']
    name = next((f'{key}.npy' for key in _NPZ_KEYS if f'{key}.npy' in names),
                arrays[0] if len(arrays) == 1 and arrays[0].endswith('.npy')
                else None)
    if name is None:
        raise SpikeFileError(
            f'{path}: .npz holds {excerpt([n[:-4] for n in names])}; '
            f'expected a key "spikes" (or Spike-Zoo\'s "spk") or a single '
            f'array')
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
    its first data byte, with its checked layout (:func:`_npy_header`).

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
            layout = _npy_header(path, f, size)
            yield (f, ) + layout
    except SpikeFileError:
        raise
    except Exception as err:  # noqa: BLE001 zipfile, zlib and NumPy's
        # header parser raise many types for bad bytes (ValueError,
        # EOFError, zipfile.BadZipFile, zlib.error, SyntaxError, ...)
        raise SpikeFileError(f'{path}: cannot read the array: '
                             f'{type(err).__name__}: {cut(str(err))}') \
            from err


#: bytes an ``.npz`` ``layout`` member may declare (a header and a short
#: string); more is refused unread
_LAYOUT_MEMBER_BYTES = 4096


def _side_file_layout(path: str) -> List[Tuple[str, str]]:
    """``[(where, layout)]`` the side file ``<path>.json`` records
    (``{"layout": "THW"}``); empty without one, or without the key."""
    side = path + '.json'
    if not osp.exists(side):
        return []
    try:
        meta = load_json_file(side, 'side file')
    except (OSError, ValueError) as err:
        raise SpikeFileError(f'{path}: {err}') from err
    if not isinstance(meta, dict) or 'layout' not in meta:
        return []
    if not LAYOUT.accepts(meta['layout']):
        raise SpikeFileError(
            f'{path}: side file {side} says "layout": '
            f'{excerpt(meta["layout"])}; expected {LAYOUT.describe()}')
    return [(f'its side file {side}', meta['layout'])]


def _npz_layout(path: str) -> List[Tuple[str, str]]:
    """``[(where, layout)]`` an ``.npz`` records: its ``layout`` member
    (a string array, read without pickles and at most
    :data:`_LAYOUT_MEMBER_BYTES`) and its Spike-Zoo key ``spk``."""
    records, value = [], None
    member = f'{_NPZ_LAYOUT_KEY}.npy'
    try:
        with zipfile.ZipFile(path) as archive:
            if _npz_member(path, archive).filename == 'spk.npy':
                records.append(('its key "spk" (the Spike-Zoo convention)',
                                'THW'))
            if member in archive.namelist():
                info = archive.getinfo(member)
                if info.file_size > _LAYOUT_MEMBER_BYTES:
                    raise SpikeFileError(
                        f'{path}: member "{_NPZ_LAYOUT_KEY}" declares '
                        f'{info.file_size} bytes; a layout needs at most '
                        f'{_LAYOUT_MEMBER_BYTES}')
                with archive.open(info) as f:
                    value = _layout_member(path, f)
    except SpikeFileError:
        raise
    except Exception as err:  # noqa: BLE001 as in _array_file
        raise SpikeFileError(f'{path}: cannot read the array: '
                             f'{type(err).__name__}: {cut(str(err))}') \
            from err
    if value is not None:
        if not LAYOUT.accepts(value):
            raise SpikeFileError(
                f'{path}: member "{_NPZ_LAYOUT_KEY}" holds {excerpt(value)}; '
                f'expected {LAYOUT.describe()}')
        records.append((f'its member "{_NPZ_LAYOUT_KEY}"', value))
    return records


def _layout_member(path: str, f: BinaryIO) -> str:
    """The string an ``.npz`` ``layout`` member holds: a 0-d string array
    (``np.array('THW')``), its header checked before its few data bytes
    are read (nothing larger is allocated)."""
    version = np.lib.format.read_magic(f)
    read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                   else np.lib.format.read_array_header_2_0)
    shape, _, dtype = read_header(f)
    if shape != () or dtype.kind not in 'US' or dtype.itemsize > 64:
        raise SpikeFileError(
            f'{path}: member "{_NPZ_LAYOUT_KEY}" is an array of shape {shape} '
            f'and type {dtype}; expected a string, {LAYOUT.describe()}')
    data = f.read(dtype.itemsize)
    if len(data) != dtype.itemsize:
        raise SpikeFileError(f'{path}: member "{_NPZ_LAYOUT_KEY}" is '
                             f'truncated')
    value = np.frombuffer(data, dtype)[0].item()
    return value.decode('ascii', 'replace') if isinstance(value, bytes) \
        else value


def _ambiguous(path: str) -> SpikeFileError:
    """The error for an array file that records no layout, none given."""
    with _array_file(path) as (_, shape, _, _):
        pass
    first, second, third = shape
    return SpikeFileError(
        f'{path}: a {first}x{second}x{third} array that does not record its '
        f'layout: frames first, (T, H, W) = {first} frames of '
        f'{second}x{third} (layout THW), or frames last, (H, W, T) = '
        f'{third} frames of {first}x{second} (layout HWT)? Give it: '
        f'layout=\'THW\' or \'HWT\' (load_spikes, spike_shape, '
        f'LoadSpikeFromFile in a config\'s pipeline), --layout THW or HWT '
        f'on the tools, or a side file {path}.json holding '
        f'{{"layout": "THW"}} (files written by save_spikes record it)')


def _array_layout(path: str, layout: Optional[str]) -> str:
    """The layout of an ``.npy``/``.npz`` array: what the file records
    (see the module docstring), which ``layout``, when given, must agree
    with; ``layout`` where it records none; an error where neither."""
    records = _side_file_layout(path)
    if path.lower().endswith('.npz'):
        records += _npz_layout(path)
    for where, told in records[1:]:
        if told != records[0][1]:
            raise SpikeFileError(
                f'{path}: {records[0][0]} says layout {records[0][1]} but '
                f'{where} says {told}')
    if records and layout not in (None, records[0][1]):
        raise SpikeFileError(
            f'{path}: {records[0][0]} records layout {records[0][1]}, but '
            f'layout {layout} was given; leave the layout unset or give '
            f'{records[0][1]}')
    if records:
        return records[0][1]
    if layout is None:
        raise _ambiguous(path)
    return layout


def _frame_major(path: str, layout: Optional[str]) -> str:
    """``'THW'``: ``.dat``/``.spk`` store frames one after another; a
    ``layout`` of ``'HWT'`` is an error."""
    if layout not in (None, 'THW'):
        raise SpikeFileError(
            f'{path}: a {osp.splitext(path)[1]} file stores frames one after '
            f'another, (T, H, W); layout {layout} does not apply to it '
            f'(leave it unset or give THW)')
    return 'THW'


def _stream_shape(shape: Tuple[int, int, int],
                  layout: str) -> Tuple[int, int, int]:
    """``(T, H, W)`` of an array of ``shape`` stored in ``layout``."""
    return shape if layout == 'THW' else (shape[2], shape[0], shape[1])


def _read_array_window(path: str, start: int, length: Optional[int],
                       layout: str) -> np.ndarray:
    """Frames ``[start, start + length)`` of an ``.npy``/``.npz`` array
    stored in ``layout``, as ``(length, H, W)`` in its own dtype
    (``.npy``: memory-mapped, only the window copied; ``.npz``:
    :func:`_inflated_window`)."""
    if path.lower().endswith('.npz'):
        return _inflated_window(path, _content_identity(path), start,
                                length, layout)
    with _array_file(path) as (f, shape, dtype, fortran):
        steps, height, width = _stream_shape(shape, layout)
        start, length = _window(path, steps, start, length,
                                height * width * dtype.itemsize)
        array = np.memmap(path, dtype=dtype, mode='r', offset=f.tell(),
                          shape=shape, order='F' if fortran else 'C')
        if layout == 'THW':
            return np.asarray(array[start:start + length])
        return np.ascontiguousarray(
            array[:, :, start:start + length].transpose(2, 0, 1))


#: bytes of an interleaved ``.npz`` member inflated at a time
_CHUNK_BYTES = 1 << 20


def _content_identity(path: str) -> Tuple[int, ...]:
    """What tells ``path``'s content from any earlier one, as a cache key:
    device, inode, size, mtime and ctime (ns). Every write moves the
    ctime, and no user can set it back (``os.utime``, ``cp -p``,
    ``rsync -t`` and ``tar`` restore only the mtime), so a rewrite of the
    same size with the old mtime restored is still a new key."""
    stat = os.stat(path)
    return (stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns,
            stat.st_ctime_ns)


@functools.lru_cache(maxsize=1)
def _inflated_window(path: str, identity: Tuple[int, ...], start: int,
                     length: Optional[int], layout: str) -> np.ndarray:
    """Frames ``[start, start + length)`` of an ``.npz`` member stored in
    ``layout``, as ``(length, H, W)``, read-only.

    Frames stored one after another (``(T, H, W)`` in C order, ``(H, W, T)``
    in Fortran order) inflate once, in chunks, up to the window's end,
    keeping only the window. Interleaved ones (each pixel's ``T`` values
    together: ``(H, W, T)`` in C order, ``(T, H, W)`` in Fortran order)
    inflate whole, :data:`_CHUNK_BYTES` at a time, keeping only each
    pixel's window. The last window read is kept, so reading it again (the
    shape, then the frames, of one sample) inflates nothing. ``identity``
    (:func:`_content_identity`) makes a changed file a new key.
    """
    with _array_file(path) as (f, shape, dtype, fortran):
        steps, height, width = _stream_shape(shape, layout)
        frame = height * width * dtype.itemsize
        start, length = _window(path, steps, start, length, frame)
        if fortran == (layout == 'HWT'):  # frame after frame
            f.seek(f.tell() + start * frame)  # inflates and drops, in chunks
            data = f.read(length * frame)
            if len(data) != length * frame:
                raise SpikeFileError(f'{path}: the array data is truncated')
            frames = np.frombuffer(data, dtype)
            array = (frames.reshape(length, height, width) if not fortran
                     else frames.reshape(height, width, length,
                                         order='F').transpose(2, 0, 1))
        else:  # pixel after pixel, each pixel's steps together
            run = steps * dtype.itemsize
            per_chunk = max(1, _CHUNK_BYTES // run)
            window = np.empty((length, height * width), dtype)
            for first in range(0, height * width, per_chunk):
                count = min(per_chunk, height * width - first)
                data = f.read(count * run)
                if len(data) != count * run:
                    raise SpikeFileError(
                        f'{path}: the array data is truncated')
                window[:, first:first + count] = np.frombuffer(
                    data, dtype).reshape(count, steps)[:, start:start +
                                                       length].T
            # pixels in C order of (H, W), or (Fortran (T, H, W)) of (W, H)
            array = (np.ascontiguousarray(window.reshape(
                length, width, height).transpose(0, 2, 1)) if fortran
                     else window.reshape(length, height, width))
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


def _read_dat(path, shape, start, length, layout):
    return _read_packed(path, shape, start, length, 0, bottom_up=True)


def _read_spk(path, shape, start, length, layout):
    return _read_packed(path, shape, start, length, _HEADER.size,
                        bottom_up=False)


def _array_shape(path: str, height: Optional[int], width: Optional[int],
                 layout: str) -> Tuple[int, int, int]:
    """``(T, H, W)`` of the ``.npy``/``.npz`` array stored in ``layout``,
    from its checked header (the array records its size: a caller's
    ``height``/``width`` must agree with it)."""
    with _array_file(path) as (_, shape, _, _):
        steps, own_height, own_width = _stream_shape(shape, layout)
    _check_caller_size(path, f'its {layout} array of shape {shape}',
                       (own_height, own_width), height, width)
    return steps, own_height, own_width


def _read_array(path, shape, start, length, layout):
    window = _read_array_window(path, start, length, layout)
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
    np.savez_compressed(buffer, spikes=spikes,
                        **{_NPZ_LAYOUT_KEY: np.array('THW')})
    return buffer.getvalue()


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
        :mod:`~wgse_mmseg.core.limits` (``height``/``width``: the caller's,
        or ``None``; formats that record their size ignore them).
    ``read(path, shape, start, length, layout)``
        frames ``[start, start + length)`` (``length=None``: to the end)
        of the file ``shape`` and ``layout`` describe, as a
        ``(length, H, W)`` ``uint8`` array of 0/1, the window checked by
        :func:`_window` and the values checked to be 0/1 where the format
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
    SpikeFormat('.dat', _frame_major,
                lambda path, height, width, layout: _dat_geometry(
                    path, height, width), _read_dat, _encode_dat),
    SpikeFormat('.spk', _frame_major,
                lambda path, height, width, layout: _spk_geometry(
                    path, height, width),
                _read_spk, _encode_spk),
    SpikeFormat('.npy', _array_layout, _array_shape, _read_array,
                _encode_npy, side={'layout': 'THW'}),
    SpikeFormat('.npz', _array_layout, _array_shape, _read_array,
                _encode_npz),
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
    (:func:`~wgse_mmseg.core.output_folder.check_input_file`)."""
    fmt = _format(path)
    check_input_file(path, 'spike file', SpikeFileError)
    return fmt


@declare(path=Path(), height=_SIDE, width=_SIDE, layout=LAYOUT.or_none())
def spike_shape(path: str, height: Optional[int] = None,
                width: Optional[int] = None,
                layout: Optional[str] = None) -> Tuple[int, int, int]:
    """``(T, H, W)`` of a spike file without reading its frames
    (arguments as :func:`load_spikes`'s)."""
    path = os.fspath(path)
    fmt = _existing(path)
    return fmt.shape(path, height, width, fmt.layout(path, layout))


@declare(path=Path(), height=_SIDE, width=_SIDE, start=Integer(0),
         length=Integer(1, optional=True), layout=LAYOUT.or_none())
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
    """
    path = os.fspath(path)
    fmt = _existing(path)
    layout = fmt.layout(path, layout)
    shape = fmt.shape(path, height, width, layout)
    return fmt.read(path, shape, start, length, layout)


@declare(path=Path())
def save_spikes(path: str, spikes: np.ndarray) -> WrittenFile:
    """Write a ``(T, H, W)`` 0/1 array to ``path`` (format from extension),
    recording its layout ``'THW'`` where the format does not fix it
    (``.npz``: a member ``layout``; ``.npy``: the side file
    ``<path>.json``, written first).

    Each file appears complete or not at all. Returns what was written to
    ``path``, as a named tuple: ``size`` and ``sha256`` of the bytes, from
    memory.
    """
    path = os.fspath(path)
    fmt = _format(path)
    spikes = np.asarray(spikes)
    if spikes.ndim != 3 or 0 in spikes.shape:
        raise SpikeFileError(
            f'{path}: expected a non-empty (T, H, W) array, got shape '
            f'{spikes.shape}')
    _check_binary(path, spikes)
    encoded = fmt.encode(path, spikes.astype(np.uint8))
    if fmt.side is not None:
        write_bytes(path + '.json', json.dumps(fmt.side).encode())
    return write_bytes(path, encoded)
