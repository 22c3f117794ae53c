"""Walking a recording: a window every ``stride`` readouts, into a video.

A spike camera records continuously; a walk runs a *window model* on the
window of ``length`` readouts centred on every ``stride``-th readout of a
recording of any length, and writes what it made of each window as one
frame of a video. The one mechanism of ``tools/demo.py --stride`` (a
segmentation overlay per window) and ``tools/misc/reconstruct.py --stride``
(a reconstructed image per window); it needs no OpenMMLab.

The plan (:func:`~wgse_mmseg.apis.walk_plan.plan_walk`)
    Windows are centred on readouts ``0, stride, 2 * stride, ...`` of the
    recording; the first walked centre is the first of those whose
    ``length``-readout window (frames ``[centre - length // 2, centre -
    length // 2 + length)``, as
    :func:`~wgse_mmseg.core.spike_formats.centered_window`) fits in the
    recording, the last the last that fits; the centres that do not fit at
    either end are skipped and reported (:meth:`WalkPlan.describe`).
Reading
    Windows are read a batch at a time with
    :func:`~wgse_mmseg.fileio.load_spikes` (memory-mapped, windowed): the
    span a batch covers once where its windows overlap or touch (``stride
    <= length``), else each window on its own, so memory is bounded by the
    batch, never by the recording.
The window model
    Any callable ``model(spikes) -> results`` taking a ``(B, T, H, W)``
    ``float32`` CPU tensor of 0/1 and returning ``B`` results (a tensor or
    a list, indexed by window); ``render(window, result)`` turns a
    ``(T, H, W)`` ``uint8`` window and its result into an 8-bit ``(H, W)``
    grey or ``(H, W, 3)`` RGB frame.
Outputs, beside ``video`` (:func:`walk_outputs`)
    ``video`` (``.mp4``: OpenCV's ``mp4v``; ``.gif``: Pillow), the CSV
    ``<video stem>.csv`` (:data:`~wgse_mmseg.apis.walk_state.CSV_COLUMNS`:
    window index, centre readout, first and end readout, ``batch``: the index
    of the first window of the model call that made it, and ``time_ms``: that
    call's time over its windows, in milliseconds) and, with ``save_frames``,
    ``<video stem>_frames/<window>.png``. Each appears complete or not at all.
Resuming
    Until the walk ends, its state lies in ``<video>.partial/``, a folder
    the walk owns (:func:`~wgse_mmseg.fileio.locks.own_folder`: one
    walk of a video at a time, a second refused naming the first, or
    waiting with ``wait``; no link in it followed): the settings it was
    started with, a PNG per window done, and ``progress.csv``, a row
    appended per window once its PNG is written, recording the PNG's size
    and SHA-256. A walk re-run with the same recording and settings keeps
    the leading rows whose PNG still holds those bytes and continues after
    them (a torn row, a missing or damaged PNG: that window and those
    after it are done again); state that cannot be read (its settings
    file damaged) is discarded and the walk starts over. One with other
    settings is refused, naming the differences and the folder to remove
    to start over, so results never mix. The video, CSV and frames are
    assembled from that folder at the end, and the folder is removed.

An MP4 of odd height or width is padded by one replicated row or column
(the codec needs even sides). A GIF is assembled in memory by Pillow (about
``H * W`` bytes a frame): use MP4 for long walks.

The plan is :mod:`.walk_plan`'s, the resume state :mod:`.walk_state`'s and
the video :mod:`.walk_video`'s.
"""
import json
import os
import os.path as osp
import sys
import time
from typing import (TYPE_CHECKING, Any, Callable, Dict, NamedTuple, Optional,
                    Sequence)

import numpy as np
from tqdm import tqdm

from ..argument_checks import (check_flag, check_integer, check_number,
                               check_path, check_read_options)
from ..command_line import Integer, Number
from ..fileio.images import write_png
from ..fileio.locks import add_wait_option, own_folder
from ..fileio.output_folder import open_append
from ..limits import MAX_BATCH_SIZE, MAX_NUM_STEPS
from .walk_plan import (STRIDE, WalkError, WalkOutputs, WalkPlan,
                        plan_recording_walk, read_windows, walk_outputs)
from .walk_state import PROGRESS_NAME, csv_line, frame_name, open_state
from .walk_video import finish_walk, png_image

if TYPE_CHECKING:  # torch where a walk runs, not for --help
    import torch

__all__ = ['WalkError', 'WalkReport', 'walk_recording']


#: windows a model call takes
BATCH_SIZE = Integer(1, MAX_BATCH_SIZE)


#: frames per second of the video
FPS = Number(0, 1000, strict_minimum=True)


class WalkReport(NamedTuple):
    """What :func:`walk_recording` did."""
    plan: WalkPlan
    outputs: WalkOutputs
    #: windows found done in the state folder of an interrupted walk
    resumed: int
    #: windows the model ran on in this call
    computed: int

    def summary(self, verb: str, save_frames: bool) -> str:
        """What a tool prints after a walk: the plan, whether it resumed
        (``verb``: what the model did to a window, ``'segmented'``), and
        the files written (the frames folder with ``save_frames``)."""
        lines = [self.plan.describe()]
        if self.resumed:
            lines.append(f'resumed an interrupted walk: {self.resumed} '
                         f'windows were done, {self.computed} {verb} now')
        lines += [self.outputs.video, self.outputs.csv]
        if save_frames:
            lines.append(self.outputs.frames)
        return '\n'.join(lines)


def _identity(path: str, height: Optional[int], width: Optional[int],
              layout: Optional[str], plan: WalkPlan,
              settings: Dict[str, Any]) -> dict:
    """What a resumed walk must share with the one it continues."""
    stat = os.stat(path)
    return dict(recording=osp.abspath(path), size=stat.st_size,
                mtime_ns=stat.st_mtime_ns, height=height, width=width,
                layout=layout, total=plan.total,
                length=plan.length, stride=plan.stride,
                settings=json.loads(json.dumps(settings, default=str)))


def walk_recording(path: str, video: str,
                   model: Callable[['torch.Tensor'], Sequence[Any]],
                   render: Callable[[np.ndarray, Any], np.ndarray],
                   length: int, stride: int, batch_size: int = 8,
                   fps: float = 10.0, settings: Optional[dict] = None,
                   save_frames: bool = False, height: Optional[int] = None,
                   width: Optional[int] = None,
                   layout: Optional[str] = None,
                   progress: bool = True, wait: bool = False) -> WalkReport:
    """Walk the recording ``path`` into ``video`` (see the module).

    Args:
        path: a spike file (``.dat``, ``.spk``, ``.npy``, ``.npz``).
        video: the ``.mp4`` or ``.gif`` to write; the CSV, frames and state
            folder lie beside it (``<stem>.csv``, ``<stem>_frames/``,
            ``<video>.partial/``).
        model: ``(B, T, H, W)`` float32 CPU tensor of 0/1 -> ``B`` results.
        render: ``((T, H, W) uint8 window, its result)`` -> 8-bit ``(H, W)``
            grey or ``(H, W, 3)`` RGB frame.
        length: readouts per window (``T``); stride: readouts between
            centres; batch_size: windows per model call; fps: of the video.
        settings: JSON values that fix what the frames look like (the
            model, its options); an interrupted walk resumes only with the
            same ones.
        save_frames: keep each frame as ``<video stem>_frames/NNNNNN.png``.
        height, width: frame size of a ``.dat`` file.
        layout: ``'THW'``/``'HWT'`` of an ``.npy``/``.npz`` that does not
            record it (:func:`~wgse_mmseg.fileio.load_spikes`).
        progress: a progress bar on stderr.
        wait: wait for another walk of ``video`` to finish instead of
            raising.

    Raises:
        WalkError: for a video path that is not ``.mp4``/``.gif``, a
            recording shorter than one window, the state of an
            interrupted walk with other settings, or a folder where the
            video or the CSV goes.
        OutputFolderError: another process walks into ``video``.
        SpikeFileError: for a recording that cannot be read.
        ArgumentError: for an argument of the wrong kind.
    """
    entry = 'walk_recording'
    for name, value in (('path', path), ('video', video)):
        check_path(entry, name, value)
    check_integer(entry, 'length', length, 1, MAX_NUM_STEPS)
    check_integer(entry, 'stride', stride, 1)
    check_integer(entry, 'batch_size', batch_size, 1, MAX_BATCH_SIZE)
    check_number(entry, 'fps', fps, 0, 1000, strict_minimum=True)
    check_read_options(entry, height, width, layout)
    for name, value in (('save_frames', save_frames),
                        ('progress', progress), ('wait', wait)):
        check_flag(entry, name, value)
    plan = plan_recording_walk(path, length, stride, height, width, layout)
    outputs = walk_outputs(video, save_frames, [path])
    identity = _identity(path, height, width, layout, plan, settings or {})
    with own_folder(outputs.partial, wait=wait, named=True) as state:
        resumed = open_state(state, identity, plan)
        _walk(path, outputs, model, render, plan, resumed, batch_size,
              (height, width, layout), progress)
        finish_walk(state, outputs, len(plan.centres), fps, save_frames)
    return WalkReport(plan, outputs, resumed, len(plan.centres) - resumed)


def _walk(path: str, outputs: WalkOutputs, model, render, plan: WalkPlan,
          resumed: int, batch_size: int, reading: tuple,
          progress: bool) -> None:
    """Run ``model`` on the windows of ``plan`` after the first
    ``resumed``, each frame written to the state folder and logged in
    ``progress.csv`` (``reading``: ``height``, ``width``, ``layout`` of
    the recording)."""
    import torch
    todo = plan.centres[resumed:]
    bar = tqdm(total=len(plan.centres), initial=resumed, unit='window',
               desc=osp.basename(path), file=sys.stderr,
               disable=not progress)
    with bar, open_append(osp.join(outputs.partial, PROGRESS_NAME)) as log:
        for first in range(0, len(todo), batch_size):
            centres = todo[first:first + batch_size]
            windows = read_windows(path, plan, centres, *reading)
            began = time.perf_counter()
            results = model(torch.from_numpy(windows).float())
            per_window = (time.perf_counter() - began) * 1000 / len(centres)
            for offset, centre in enumerate(centres):
                index = resumed + first + offset
                written = write_png(
                    osp.join(outputs.partial, frame_name(index)),
                    png_image(render(windows[offset], results[offset])))
                log.write(csv_line([
                    index, centre, plan.start(centre),
                    plan.start(centre) + plan.length, resumed + first,
                    f'{per_window:.3f}', written.size, written.sha256]))
                log.flush()
            bar.update(len(centres))


def add_walk_options(parser) -> None:
    """The walk's options of a tool's command line: ``--stride`` (which
    makes the tool walk), ``--batch-size``, ``--fps``, ``--save-frames``."""
    parser.add_argument(
        '--stride', type=STRIDE,
        help='walk the recording: a window centred on every STRIDE-th '
        'readout into a video (the output\'s extension: .mp4 or .gif), '
        'with a CSV of the windows beside it; resumes an interrupted walk')
    parser.add_argument('--batch-size', type=BATCH_SIZE, default=8,
                        help='windows per model call of a walk (default 8)')
    parser.add_argument('--fps', type=FPS, default=10.0,
                        help='frames per second of a walk\'s video '
                        '(default 10)')
    parser.add_argument('--save-frames', action='store_true',
                        help='also keep a walk\'s frames as PNGs in '
                        '<output stem>_frames/')
    add_wait_option(parser)
