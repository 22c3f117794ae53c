"""Walking a recording: a window every ``stride`` readouts, into a video.

A spike camera records continuously; a walk runs a *window model* on the
window of ``length`` readouts centred on every ``stride``-th readout of a
recording of any length, and writes what it made of each window as one
frame of a video. The one mechanism of ``tools/demo.py --stride`` (a
segmentation overlay per window) and ``tools/misc/reconstruct.py --stride``
(a reconstructed image per window); it needs no OpenMMLab.

The plan (:func:`plan_walk`)
    Windows are centred on readouts ``0, stride, 2 * stride, ...`` of the
    recording; the first walked centre is the first of those whose
    ``length``-readout window (frames ``[centre - length // 2, centre -
    length // 2 + length)``, as :func:`~wgse_mmseg.core.io.centered_window`)
    fits in the recording, the last the last that fits; the centres that do
    not fit at either end are skipped and reported
    (:meth:`WalkPlan.describe`).
Reading
    Windows are read a batch at a time with
    :func:`~wgse_mmseg.core.io.load_spikes` (memory-mapped, windowed): the
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
    ``<video stem>.csv`` (:data:`CSV_COLUMNS`: window index, centre
    readout, first and end readout, ``batch``: the index of the first
    window of the model call that made it, and ``time_ms``: that call's
    time over its windows, in milliseconds) and,
    with ``save_frames``, ``<video stem>_frames/<window>.png``. Each appears
    complete or not at all.
Resuming
    Until the walk ends, its state lies in ``<video>.partial/``, a folder
    the walk owns (:func:`~wgse_mmseg.core.output_folder.own_folder`: one
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
"""
import json
import os
import os.path as osp
import sys
import time
from typing import (TYPE_CHECKING, Any, Callable, Dict, List, NamedTuple,
                    Optional, Sequence)

import numpy as np
from tqdm import tqdm

from .arguments import (LAYOUT, NUM_STEPS, SIDE, Flag, Integer, Number, Path,
                        declare)
from .io import (atomic_output, atomic_path, load_spikes, spike_shape,
                 write_bytes, write_png)
from .limits import MAX_BATCH_SIZE, check_utf8_path, load_json_file
from .markers import file_digest
from .output_folder import (OwnedFolder, add_wait_option, check_named_folder,
                            check_output, check_output_folder,
                            check_output_kind, note_written, open_append,
                            own_folder)

if TYPE_CHECKING:  # torch and OpenCV where a walk runs, not for --help
    import torch

__all__ = ['WalkError', 'WalkReport', 'walk_recording']

#: the video formats, by lower-case extension of ``video``
VIDEO_EXTENSIONS = ('.mp4', '.gif')
#: the CSV's columns, one row per walked window
CSV_COLUMNS = ('window', 'centre', 'start', 'end', 'batch', 'time_ms')
#: readouts between window centres
STRIDE = Integer(1)
#: windows a model call takes
BATCH_SIZE = Integer(1, MAX_BATCH_SIZE)
#: frames per second of the video
FPS = Number(0, 1000, strict_minimum=True)

_SETTINGS = 'settings.json'
_PROGRESS = 'progress.csv'
#: a row of ``progress.csv``: the CSV's, then the size and SHA-256 of the
#: window's PNG as written
_PROGRESS_COLUMNS = CSV_COLUMNS + ('size', 'sha256')
#: the longest row ``progress.csv`` holds (a longer one is damage)
_ROW_BYTES = 256


class WalkError(ValueError):
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


@declare(total=Integer(1), length=NUM_STEPS, stride=STRIDE)
def plan_walk(total: int, length: int, stride: int) -> WalkPlan:
    """The windows of a ``total``-readout recording that a walk with
    ``length``-readout windows every ``stride`` readouts visits."""
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
    :func:`~wgse_mmseg.core.output_folder.check_output_folder`), are an
    :class:`~wgse_mmseg.core.output_folder.OutputFolderError` naming
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
    ``width``, ``layout``: as :func:`~wgse_mmseg.core.io.load_spikes`
    takes them)."""
    starts = [plan.start(c) for c in centres]
    if plan.stride <= plan.length:
        span = load_spikes(path, height, width, starts[0],
                           starts[-1] + plan.length - starts[0], layout)
        return np.stack([span[s - starts[0]:s - starts[0] + plan.length]
                         for s in starts])
    return np.stack([load_spikes(path, height, width, s, plan.length, layout)
                     for s in starts])


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


def _frame_name(index: int) -> str:
    return f'{index:06d}.png'


def _frame_verifies(state: OwnedFolder, index: int, size: str,
                    sha256: str) -> bool:
    """Whether window ``index``'s PNG is a regular file holding the
    ``size`` bytes of SHA-256 ``sha256`` its row records."""
    path = state.file(osp.join(state.root, _frame_name(index)))
    return (osp.exists(path) and str(os.stat(path).st_size) == size
            and file_digest(path) == sha256)


def _windows_done(state: OwnedFolder, plan: WalkPlan) -> int:
    """How many leading rows of ``progress.csv`` are complete, in order,
    match ``plan`` and have their PNG as recorded; the file is rewritten
    (a new file, whatever was at its path) with just them."""
    progress = state.file(osp.join(state.root, _PROGRESS))
    done = 0
    with atomic_output(progress) as kept:
        if osp.exists(progress):
            with open(progress, 'rb') as f:
                for line in iter(lambda: f.readline(_ROW_BYTES), b''):
                    row = line.decode('utf-8', 'replace').rstrip('\n')
                    row = row.split(',')
                    if (not line.endswith(b'\n')  # torn by an interruption
                            or len(row) != len(_PROGRESS_COLUMNS)
                            or done >= len(plan.centres)
                            or row[:4] != _row_start(plan, done)
                            or not _frame_verifies(state, done, *row[-2:])):
                        break
                    kept.write(line)
                    done += 1
    return done


def _row_start(plan: WalkPlan, index: int) -> List[str]:
    """The first columns of window ``index``'s row: index, centre, start,
    end."""
    centre = plan.centres[index]
    return [str(index), str(centre), str(plan.start(centre)),
            str(plan.start(centre) + plan.length)]


def _csv_line(row: Sequence[Any]) -> bytes:
    """One CSV row of numbers (or the header), ``\n``-terminated."""
    return (','.join(map(str, row)) + '\n').encode()


def _open_state(state: OwnedFolder, identity: dict, plan: WalkPlan) -> int:
    """The state folder, checked against ``identity`` or started afresh
    (when empty, or its settings file cannot be read); the number of
    windows already done."""
    settings = state.file(osp.join(state.root, _SETTINGS))
    recorded = None
    if osp.exists(settings):
        try:
            recorded = load_json_file(settings, 'walk settings file')
        except (OSError, ValueError):
            pass  # damaged: nothing in the folder can be trusted
    if recorded is None:
        state.clear()
        write_bytes(osp.join(state.root, _PROGRESS), b'')
        write_bytes(settings, json.dumps(identity, indent=1).encode())
        return 0
    if recorded != identity:
        keys = sorted(set(identity) | set(recorded if isinstance(
            recorded, dict) else {}))
        changed = [k for k in keys if not isinstance(recorded, dict)
                   or recorded.get(k) != identity.get(k)]
        raise WalkError(
            f'{state.root}: holds an interrupted walk with other '
            f'settings ({", ".join(changed)} differ: '
            f'{_differences(recorded, identity, changed)}); its frames '
            f'are not mixed with these: re-run with its settings to '
            f'finish it, or remove the folder to start over')
    return _windows_done(state, plan)


def _differences(recorded: Any, identity: dict, keys: List[str]) -> str:
    if not isinstance(recorded, dict):
        return 'the recorded settings are not a mapping'
    return '; '.join(f'{k} was {str(recorded.get(k))[:80]}, now '
                     f'{str(identity.get(k))[:80]}' for k in keys)


def _png_image(frame: np.ndarray) -> np.ndarray:
    """An 8-bit grey or RGB frame as :func:`write_png` takes it (grey, or
    OpenCV's BGR)."""
    frame = np.asarray(frame)
    if frame.dtype != np.uint8 or frame.ndim not in (2, 3) or (
            frame.ndim == 3 and frame.shape[2] != 3):
        raise WalkError(f'render must return an 8-bit (H, W) or (H, W, 3) '
                        f'frame, got {frame.dtype} of shape {frame.shape}')
    return frame if frame.ndim == 2 else np.ascontiguousarray(
        frame[..., ::-1])


def _frames(outputs: WalkOutputs, count: int):
    """The ``count`` saved frames (grey or colour), BGR, all of one
    size."""
    import cv2
    size = None
    for index in range(count):
        path = osp.join(outputs.partial, _frame_name(index))
        frame = cv2.imread(path, cv2.IMREAD_COLOR)
        if frame is None:
            raise WalkError(f'{path}: a frame of the walk is missing or '
                            f'unreadable; re-run to make it again')
        if size is None:
            size = frame.shape
        elif frame.shape != size:
            raise WalkError(f'{path}: frame of shape {frame.shape}, the '
                            f'first was {size}; a video needs one size')
        yield frame


def _write_video(outputs: WalkOutputs, count: int, fps: float) -> None:
    """Assemble the saved frames into ``outputs.video`` atomically."""
    with atomic_path(outputs.video) as tmp:
        if outputs.video.lower().endswith('.gif'):
            from PIL import Image
            images = (Image.fromarray(np.ascontiguousarray(f[..., ::-1]))
                      for f in _frames(outputs, count))
            first = next(images)
            first.save(tmp, format='GIF', save_all=True,
                       append_images=images, duration=1000 / fps, loop=0)
            return
        import cv2
        writer = None
        try:
            for frame in _frames(outputs, count):
                height, width = frame.shape[:2]
                frame = cv2.copyMakeBorder(frame, 0, height % 2, 0,
                                           width % 2, cv2.BORDER_REPLICATE)
                if writer is None:
                    writer = cv2.VideoWriter(
                        tmp, cv2.VideoWriter_fourcc(*'mp4v'), fps,
                        frame.shape[1::-1])
                    if not writer.isOpened():
                        raise WalkError(f'{outputs.video}: OpenCV cannot '
                                        f'write MP4 (mp4v) here; write a '
                                        f'.gif instead')
                writer.write(frame)
        finally:
            if writer is not None:
                writer.release()


def _finish(state: OwnedFolder, outputs: WalkOutputs, count: int,
            fps: float, save_frames: bool) -> None:
    """Video, CSV and frames of the ``count`` windows from the state
    folder (a link at their paths replaced, never followed); the frames
    folder's earlier frames removed (those the package wrote: files of
    others stay); the state folder removed."""
    _write_video(outputs, count, fps)
    with atomic_output(outputs.csv) as out, \
            open(osp.join(outputs.partial, _PROGRESS), 'rb') as rows:
        out.write(_csv_line(CSV_COLUMNS))
        for line in rows:
            out.write(b','.join(line.split(b',')[:len(CSV_COLUMNS)]) + b'\n')
    if save_frames:
        with own_folder(outputs.frames, named=True) as frames:
            frames.clear()
            for index in range(count):
                name = _frame_name(index)
                target = frames.file(osp.join(outputs.frames, name))
                check_output(target)
                os.replace(osp.join(outputs.partial, name), target)
                note_written(target)
    state.remove()


@declare(path=Path(), video=Path(), length=NUM_STEPS, stride=STRIDE,
         batch_size=BATCH_SIZE, fps=FPS, save_frames=Flag(),
         height=SIDE.or_none(), width=SIDE.or_none(),
         layout=LAYOUT.or_none(), progress=Flag(), wait=Flag())
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
            record it (:func:`~wgse_mmseg.core.io.load_spikes`).
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
    """
    plan = plan_recording_walk(path, length, stride, height, width, layout)
    outputs = walk_outputs(video, save_frames, [path])
    identity = _identity(path, height, width, layout, plan, settings or {})
    with own_folder(outputs.partial, wait=wait, named=True) as state:
        resumed = _open_state(state, identity, plan)
        _walk(path, outputs, model, render, plan, resumed, batch_size,
              (height, width, layout), progress)
        _finish(state, outputs, len(plan.centres), fps, save_frames)
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
    with bar, open_append(osp.join(outputs.partial, _PROGRESS)) as log:
        for first in range(0, len(todo), batch_size):
            centres = todo[first:first + batch_size]
            windows = read_windows(path, plan, centres, *reading)
            began = time.perf_counter()
            results = model(torch.from_numpy(windows).float())
            per_window = (time.perf_counter() - began) * 1000 / len(centres)
            for offset, centre in enumerate(centres):
                index = resumed + first + offset
                written = write_png(
                    osp.join(outputs.partial, _frame_name(index)),
                    _png_image(render(windows[offset], results[offset])))
                log.write(_csv_line([
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
