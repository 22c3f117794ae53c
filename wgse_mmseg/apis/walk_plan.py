"""The plan of a walk over a recording (:mod:`.recording_walk`): which
windows, centred where, read how, and the outputs beside the video.
"""
import os
import os.path as osp
from typing import NamedTuple, Optional, Sequence

import numpy as np

from ..argument_checks import check_integer
from ..command_line import Integer
from ..errors import WgseError
from ..fileio.bounded_reads import check_utf8_path
from ..fileio.input_guard import check_output, check_output_kind
from ..fileio.locks import check_named_folder
from ..fileio.output_folder import check_output_folder
from ..fileio.spike_files import load_spikes, spike_shape
from ..limits import MAX_NUM_STEPS

__all__ = []

#: the video formats, by lower-case extension of ``video``
VIDEO_EXTENSIONS = ('.mp4', '.gif')


#: readouts between window centres
STRIDE = Integer(1)


class WalkError(WgseError, ValueError):
    """A walk that cannot run as asked; names the file or folder."""


class WalkPlan(NamedTuple):
    """Which windows a walk visits (:func:`plan_walk`)."""

    #: readouts in the recording
    total: int
    #: readouts per window (``T``)
    length: int
    #: readouts between centres
    stride: int
    #: the walked centre readouts, in order
    centres: range
    #: centres of the grid before ``centres`` whose window does not fit
    skipped_start: range
    #: centres of the grid after ``centres`` whose window does not fit
    skipped_end: range

    def start(self, centre: int) -> int:
        """The first readout of the window centred on ``centre``."""
        return centre - self.length // 2

    def describe(self) -> str:
        """One sentence: the windows walked and those skipped at the ends."""
        def listed(skipped: range) -> str:
            if not skipped:
                return 'none'
            if len(skipped) <= 3:
                return ', '.join(map(str, skipped))
            return (f'{len(skipped)} centres {skipped[0]}..{skipped[-1]} '
                    f'every {self.stride}')
        walked = (f'{len(self.centres)} windows of {self.length} readouts '
                  f'centred on readouts {self.centres[0]}..'
                  f'{self.centres[-1]} every {self.stride}'
                  if self.centres else 'no window')
        return (f'{walked} in a recording of {self.total} readouts; '
                f'skipped, their window not fitting: at the start '
                f'{listed(self.skipped_start)}, at the end '
                f'{listed(self.skipped_end)}')


def plan_walk(total: int, length: int, stride: int) -> WalkPlan:
    """The windows of a ``total``-readout recording that a walk with
    ``length``-readout windows every ``stride`` readouts visits."""
    check_integer('plan_walk', 'total', total, 1)
    check_integer('plan_walk', 'length', length, 1, MAX_NUM_STEPS)
    check_integer('plan_walk', 'stride', stride, 1)
    half = length // 2
    grid_end = (total - 1) // stride + 1  # grid points 0..total-1
    first = -(-half // stride)  # first k with k * stride - half >= 0
    last = (total - length + half) // stride  # last k whose window fits
    first, last = min(first, grid_end), min(max(last, first - 1),
                                            grid_end - 1)
    return WalkPlan(total, length, stride,
                    range(first * stride, (last + 1) * stride, stride),
                    range(0, first * stride, stride),
                    range((last + 1) * stride, grid_end * stride, stride))


def plan_recording_walk(path: str, length: int, stride: int,
                        height: Optional[int] = None,
                        width: Optional[int] = None,
                        layout: Optional[str] = None) -> WalkPlan:
    """:func:`plan_walk` of the recording ``path`` (its header read, no
    window), refusing a walk that visits no window: a tool calls it before
    it loads a model.

    Raises:
        WalkError: naming ``path``, the longest window it holds (a
            ``length`` longer than the recording) or the largest stride
            that reaches a centre that fits.
    """
    total = spike_shape(path, height, width, layout)[0]
    plan = plan_walk(total, length, stride)
    if not plan.centres:
        raise WalkError(
            f'{path}: no window of length={length} readouts centred on a '
            f'multiple of stride={stride} fits in the recording\'s {total} '
            f'readouts; ' + (
                f'the longest window it holds is {total} readouts'
                if length > total else f'a stride of at most '
                f'{total - length + 1} reaches a centre that fits'))
    return plan


class WalkOutputs(NamedTuple):
    """The files of a walk to ``video`` (:func:`walk_outputs`)."""
    video: str
    csv: str
    frames: str
    partial: str


def walk_outputs(video: str, save_frames: bool = False,
                 inputs: Sequence[str] = ()) -> WalkOutputs:
    """``video``, its CSV ``<stem>.csv``, frames folder ``<stem>_frames``
    and state folder ``<video>.partial``, checked before any work (a tool
    calls it before it loads a model): a ``video`` that is not
    ``.mp4``/``.gif`` is a :class:`WalkError`, one whose path is not UTF-8
    a ``ValueError``; a video or CSV path where no regular file can go
    (a FIFO, a device: the walk's files lie beside it), and a state or
    (``save_frames``) frames folder the package did not make or that
    holds an input (one of ``inputs``, the recording, or one read so far:
    :func:`~wgse_mmseg.fileio.output_folder.check_output_folder`), are an
    :class:`~wgse_mmseg.fileio.input_guard.OutputFolderError` naming
    it."""
    stem, ext = osp.splitext(os.fspath(video))
    check_utf8_path(video, 'OpenCV')  # it writes the video and frames
    if ext.lower() not in VIDEO_EXTENSIONS:
        raise WalkError(f'{video}: a walk writes a video, '
                        f'{" or ".join(VIDEO_EXTENSIONS)} by the extension; '
                        f'got {ext or "no extension"!r}')
    outputs = WalkOutputs(video, stem + '.csv', stem + '_frames',
                          video + '.partial')
    for output in (outputs.video, outputs.csv):
        if osp.isdir(output) and not osp.islink(output):
            raise WalkError(f'{output}: a folder where the walk writes a '
                            f'file; move it away')
        check_output(output)
        check_output_kind(output, streamed=False)
    for folder in (outputs.partial, outputs.frames)[:1 + save_frames]:
        check_named_folder(folder)
        check_output_folder(folder, inputs)
    return outputs


def read_windows(path: str, plan: WalkPlan, centres: Sequence[int],
                 height: Optional[int] = None,
                 width: Optional[int] = None,
                 layout: Optional[str] = None) -> np.ndarray:
    """The windows of ``plan`` centred on ``centres`` (increasing), as a
    ``(B, T, H, W)`` ``uint8`` array of 0/1, reading the span they cover
    once where they overlap or touch, else each on its own (``height``,
    ``width``, ``layout``: as
    :func:`~wgse_mmseg.fileio.load_spikes` takes them)."""
    starts = [plan.start(c) for c in centres]
    if plan.stride <= plan.length:
        span = load_spikes(path, height, width, starts[0],
                           starts[-1] + plan.length - starts[0], layout)
        return np.stack([span[s - starts[0]:s - starts[0] + plan.length]
                         for s in starts])
    return np.stack([load_spikes(path, height, width, s, plan.length, layout)
                     for s in starts])
