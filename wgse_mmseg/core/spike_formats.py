"""Spike stream formats: what the bytes of each kind of spike file mean.

Formats, chosen by the file extension, each one entry of
:data:`wgse_mmseg.fileio.spike_files.SPIKE_FORMATS`:

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
    (:data:`~wgse_mmseg.argument_checks.LAYOUTS`): ``'THW'``, frames first,
    ``(T, H, W)``; or ``'HWT'``, frames last, ``(H, W, T)``, as some
    simulators and viewers store them.


This module holds what the formats are, as pure functions on arrays and
bytes: the ``.spk`` header, the bit packing, the encoders, the window and
size checks; :mod:`wgse_mmseg.fileio` reads and writes files.
"""
import io
import struct
from typing import Optional, Tuple

import numpy as np

from ..errors import WgseError
from ..limits import READ_LIMIT_BYTES

__all__ = []

SPK_MAGIC = b'WGSESPK1'


SPK_VERSION = 1


SPK_HEADER = struct.Struct('<8sIIII8x')  # magic, version, T, H, W, reserved


class SpikeFileError(WgseError, ValueError):
    """A spike file that cannot be read as asked; names the file."""


def check_binary(path: str, spikes: np.ndarray) -> None:
    if not ((spikes == 0) | (spikes == 1)).all():
        raise SpikeFileError(f'{path}: spikes must hold only 0 and 1')


def frame_bytes(height: int, width: int) -> int:
    return (height * width + 7) // 8


def check_caller_size(path: str, record: str, recorded: Tuple[int, int],
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


def check_window(path: str, total: int, start: int, length: Optional[int],
                 frame_size: int) -> Tuple[int, int]:
    """``(start, length)`` of a window of a ``total``-frame stream, checked
    to fit and, at ``frame_size`` bytes a frame once read, to stay within
    :data:`~wgse_mmseg.limits.READ_LIMIT_BYTES`."""
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
            f'{READ_LIMIT_BYTES}-byte read limit (wgse_mmseg.limits.'
            f'READ_LIMIT_BYTES); read a shorter window (start, length)')
    return start, length


def unpack_frames(raw: np.ndarray, length: int, height: int,
                  width: int) -> np.ndarray:
    bits = np.unpackbits(raw.reshape(length, -1), axis=1, bitorder='little')
    return bits[:, :height * width].reshape(length, height, width)


def pack_frames(spikes: np.ndarray) -> np.ndarray:
    steps = spikes.shape[0]
    return np.packbits(spikes.reshape(steps, -1), axis=1, bitorder='little')


#: the ``.npz`` keys that hold spikes, in order of preference: this
#: package's, then the Spike-Zoo toolbox's (whose layout is ``'THW'``)
NPZ_KEYS = ('spikes', 'spk')


#: the ``.npz`` key recording the array's layout
NPZ_LAYOUT_KEY = 'layout'


def encode_dat(path: str, spikes: np.ndarray) -> bytes:
    height, width = spikes.shape[1:]
    if (height * width) % 8:
        raise SpikeFileError(
            f'{path}: .dat needs height*width divisible by 8, got '
            f'{height}x{width}')
    return pack_frames(spikes[:, ::-1]).tobytes()


def encode_spk(path: str, spikes: np.ndarray) -> bytes:
    return SPK_HEADER.pack(SPK_MAGIC, SPK_VERSION, *spikes.shape) + \
        pack_frames(spikes).tobytes()


def encode_npy(path: str, spikes: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, spikes)
    return buffer.getvalue()


def encode_npz(path: str, spikes: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.savez_compressed(buffer, spikes=spikes,
                        **{NPZ_LAYOUT_KEY: np.array('THW')})
    return buffer.getvalue()
