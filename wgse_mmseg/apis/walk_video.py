"""The video of a walk (:mod:`.recording_walk`): its frames as 8-bit
images, written into ``video`` (MP4 or GIF) once every window is done.
"""
import os
import os.path as osp

import numpy as np

from ..fileio.atomic import atomic_output, atomic_path
from ..fileio.input_guard import check_output
from ..fileio.locks import own_folder
from ..fileio.output_folder import OwnedFolder, note_written
from .walk_plan import WalkError, WalkOutputs
from .walk_state import CSV_COLUMNS, PROGRESS_NAME, csv_line, frame_name

__all__ = []


def png_image(frame: np.ndarray) -> np.ndarray:
    """An 8-bit grey or RGB frame as
    :func:`~wgse_mmseg.fileio.images.write_png` takes it (grey, or
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
        path = osp.join(outputs.partial, frame_name(index))
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


def finish_walk(state: OwnedFolder, outputs: WalkOutputs, count: int,
                fps: float, save_frames: bool) -> None:
    """Video, CSV and frames of the ``count`` windows from the state
    folder (a link at their paths replaced, never followed); the frames
    folder's earlier frames removed (those the package wrote: files of
    others stay); the state folder removed."""
    _write_video(outputs, count, fps)
    with atomic_output(outputs.csv) as out, \
            open(osp.join(outputs.partial, PROGRESS_NAME), 'rb') as rows:
        out.write(csv_line(CSV_COLUMNS))
        for line in rows:
            out.write(b','.join(line.split(b',')[:len(CSV_COLUMNS)]) + b'\n')
    if save_frames:
        with own_folder(outputs.frames, named=True) as frames:
            frames.clear()
            for index in range(count):
                name = frame_name(index)
                target = frames.file(osp.join(outputs.frames, name))
                check_output(target)
                os.replace(osp.join(outputs.partial, name), target)
                note_written(target)
    state.remove()
