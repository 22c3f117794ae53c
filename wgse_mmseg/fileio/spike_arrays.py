"""``.npy`` and ``.npz`` spike files (:mod:`.spike_files`): their header and
member checked before anything is read, their layout from what they record
or the caller, and a window of frames read memory-mapped, or inflated once
up to its end (an interleaved member: whole, in chunks, keeping only the
window, cached by the file's identity).
"""
import contextlib
import functools
import math
import os
import os.path as osp
import zipfile
from typing import BinaryIO, Iterator, List, Optional, Tuple

import numpy as np

from ..argument_checks import LAYOUTS, is_choice
from ..core.spike_formats import (NPZ_KEYS, NPZ_LAYOUT_KEY, SpikeFileError,
                                  check_binary, check_caller_size,
                                  check_window)
from ..errors import cut, excerpt
from ..limits import READ_LIMIT_BYTES
from .bounded_reads import load_json_file

__all__ = []

#: the layouts a file may record, in words
_LAYOUTS_TEXT = f'one of {list(LAYOUTS)}'


def _is_layout(value) -> bool:
    """Whether ``value`` is a layout name (:data:`LAYOUTS`)."""
    return is_choice(value, LAYOUTS)


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


def _npz_member(path: str, archive: zipfile.ZipFile) -> zipfile.ZipInfo:
    """The member holding the spikes (``spikes.npy``, ``spk.npy``, or the
    only array besides a ``layout``), its declared inflated size checked
    against the read limit."""
    names = archive.namelist()
    arrays = [n for n in names if n != f'{NPZ_LAYOUT_KEY}.npy']
    name = next((f'{key}.npy' for key in NPZ_KEYS if f'{key}.npy' in names),
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
            f'limit (wgse_mmseg.limits.READ_LIMIT_BYTES)')
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
    if not _is_layout(meta['layout']):
        raise SpikeFileError(
            f'{path}: side file {side} says "layout": '
            f'{excerpt(meta["layout"])}; expected {_LAYOUTS_TEXT}')
    return [(f'its side file {side}', meta['layout'])]


def _npz_layout(path: str) -> List[Tuple[str, str]]:
    """``[(where, layout)]`` an ``.npz`` records: its ``layout`` member
    (a string array, read without pickles and at most
    :data:`_LAYOUT_MEMBER_BYTES`) and its Spike-Zoo key ``spk``."""
    records, value = [], None
    member = f'{NPZ_LAYOUT_KEY}.npy'
    try:
        with zipfile.ZipFile(path) as archive:
            if _npz_member(path, archive).filename == 'spk.npy':
                records.append(('its key "spk" (the Spike-Zoo convention)',
                                'THW'))
            if member in archive.namelist():
                info = archive.getinfo(member)
                if info.file_size > _LAYOUT_MEMBER_BYTES:
                    raise SpikeFileError(
                        f'{path}: member "{NPZ_LAYOUT_KEY}" declares '
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
        if not _is_layout(value):
            raise SpikeFileError(
                f'{path}: member "{NPZ_LAYOUT_KEY}" holds {excerpt(value)}; '
                f'expected {_LAYOUTS_TEXT}')
        records.append((f'its member "{NPZ_LAYOUT_KEY}"', value))
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
            f'{path}: member "{NPZ_LAYOUT_KEY}" is an array of shape {shape} '
            f'and type {dtype}; expected a string, {_LAYOUTS_TEXT}')
    data = f.read(dtype.itemsize)
    if len(data) != dtype.itemsize:
        raise SpikeFileError(f'{path}: member "{NPZ_LAYOUT_KEY}" is '
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


def array_layout(path: str, layout: Optional[str]) -> str:
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


def frame_major(path: str, layout: Optional[str]) -> str:
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
        start, length = check_window(path, steps, start, length,
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
        start, length = check_window(path, steps, start, length, frame)
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


def array_shape(path: str, height: Optional[int], width: Optional[int],
                layout: str) -> Tuple[int, int, int]:
    """``(T, H, W)`` of the ``.npy``/``.npz`` array stored in ``layout``,
    from its checked header (the array records its size: a caller's
    ``height``/``width`` must agree with it)."""
    with _array_file(path) as (_, shape, _, _):
        steps, own_height, own_width = _stream_shape(shape, layout)
    check_caller_size(path, f'its {layout} array of shape {shape}',
                      (own_height, own_width), height, width)
    return steps, own_height, own_width


def read_array(path, shape, start, length, layout):
    window = _read_array_window(path, start, length, layout)
    check_binary(path, window)
    return window.astype(np.uint8)
