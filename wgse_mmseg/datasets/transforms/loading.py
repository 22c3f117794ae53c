"""Loading spike streams into a data pipeline.

In a pipeline a spike stream lives in ``results['img']`` as an ``(H, W, T)``
``uint8`` array of 0/1: MMSeg's channel-last image convention, so
``PackSegInputs`` turns it into the ``(T, H, W)`` tensor that
:class:`~wgse_mmseg.models.SpikeSegDataPreProcessor` batches. Spikes stay
binary and one byte per spike until the preprocessor.
"""
from typing import Optional

import numpy as np
from mmcv.transforms import BaseTransform

from mmseg.registry import TRANSFORMS
from ...argument_checks import check_integer, check_read_options
from ...limits import MAX_NUM_STEPS
from ...core.spike_formats import centered_window
from ...fileio.spike_files import load_spikes, spike_shape

__all__ = ['LoadSpikeFromFile']


@TRANSFORMS.register_module()
class LoadSpikeFromFile(BaseTransform):
    """Load a spike stream from ``results['img_path']``.

    Reads ``.dat``, ``.spk``, ``.npy`` and ``.npz`` files (see
    :func:`wgse_mmseg.fileio.load_spikes`).

    Args:
        num_steps: frames to load. ``None`` loads the whole stream. A longer
            stream gives a window of ``num_steps`` frames centred on
            ``center`` (the middle frame by default, where the annotated
            frame of Spike-Cityscapes and REDS lies); a shorter one is an
            error naming the file and both numbers.
        height, width: frame size of ``.dat`` files (other formats, and
            ``.dat`` files with a ``.json`` side file, record it).
        center: frame the window is centred on; ``None`` for the middle.
            A window that does not fit in the stream is an error naming
            the centres that fit.
        layout: how ``.npy``/``.npz`` arrays that do not record it are
            stored, ``'THW'`` ``(T, H, W)`` or ``'HWT'`` ``(H, W, T)``;
            ``None`` (default) takes the layout each file records, and a
            file that records none is an error naming it
            (:func:`~wgse_mmseg.fileio.load_spikes`). A config
            sets it for a dataset of such files, e.g.
            ``dict(type='LoadSpikeFromFile', num_steps=41, layout='THW')``.

    Added keys: ``img`` ``(H, W, T)`` uint8, ``img_shape``, ``ori_shape``,
    ``num_steps``.
    """

    def __init__(self, num_steps: Optional[int] = None,
                 height: Optional[int] = None, width: Optional[int] = None,
                 center: Optional[int] = None, layout: Optional[str] = None):
        super().__init__()
        entry = 'LoadSpikeFromFile'
        check_integer(entry, 'num_steps', num_steps, 1, MAX_NUM_STEPS,
                      optional=True)
        check_read_options(entry, height, width, layout)
        check_integer(entry, 'center', center, 0, optional=True)
        self.num_steps = num_steps
        self.height = height
        self.width = width
        self.center = center
        self.layout = layout

    def transform(self, results: dict) -> dict:
        path = results['img_path']
        total, _, _ = spike_shape(path, self.height, self.width,
                                  layout=self.layout)
        length = total if self.num_steps is None else self.num_steps
        if length > total:
            raise ValueError(
                f'{path}: the stream has T={total} frames but the config '
                f'asks for num_steps={length}')
        center = total // 2 if self.center is None else self.center
        start = centered_window(path, total, center, length)
        return self.from_window(
            results, load_spikes(path, self.height, self.width, start, length,
                                 self.layout))

    def from_window(self, results: dict, spikes: np.ndarray) -> dict:
        """``results`` with the keys :meth:`transform` adds, from a window
        ``(T, H, W)`` of 0/1 already read (a walk over a recording reads
        the windows of a batch at once,
        :mod:`wgse_mmseg.apis.recording_walk`)."""
        results['img'] = np.ascontiguousarray(spikes.transpose(1, 2, 0))
        results['img_shape'] = spikes.shape[1:]
        results['ori_shape'] = spikes.shape[1:]
        results['num_steps'] = spikes.shape[0]
        return results

    def __repr__(self):
        return (f'{self.__class__.__name__}(num_steps={self.num_steps}, '
                f'height={self.height}, width={self.width}, '
                f'center={self.center}, layout={self.layout!r})')
