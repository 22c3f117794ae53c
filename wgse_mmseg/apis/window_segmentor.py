"""A segmentor and its config's test pipeline as a *window model*.

A walk over a recording (:mod:`wgse_mmseg.apis.recording_walk`) reads the
windows of a batch itself and hands them to a callable ``(B, T, H, W)``
spikes -> results. :class:`PipelineSegmentor` is that callable for a
segmentor in PyTorch: each window goes through exactly what the config's
test pipeline does after ``LoadSpikeFromFile`` reads a window
(:meth:`~wgse_mmseg.datasets.transforms.LoadSpikeFromFile.from_window`,
then the transforms after it), then the batch through ``model.test_step``,
so a walked window gets the prediction ``tools/demo.py`` gives for that
window on its own::

    pipeline = build_pipeline(cfg)            # tools/demo.py's
    segment = PipelineSegmentor(model, pipeline, 'clip.dat')
    labels = segment(spikes)                   # (B, T, H, W) -> (B, H, W)
"""
from .._openmmlab import check_mmseg_layer

check_mmseg_layer('wgse_mmseg.apis.window_segmentor')  # before MMSeg

import torch
from mmengine.dataset import Compose

from ..datasets.transforms import LoadSpikeFromFile
from ..utils.cross_checks import check_input_fits

__all__ = []


def pipeline_loader(pipeline: Compose) -> LoadSpikeFromFile:
    """The ``LoadSpikeFromFile`` of a built test pipeline (its
    ``num_steps`` is the window length)."""
    for transform in pipeline.transforms:
        if isinstance(transform, LoadSpikeFromFile):
            return transform
    raise ValueError('the test pipeline has no LoadSpikeFromFile; is it a '
                     'spike config?')


class PipelineSegmentor:
    """``(B, T, H, W)`` float spikes of 0/1 -> ``(B, H, W)`` int64 labels
    (CPU), by the test pipeline's steps after loading and
    ``model.test_step``.

    Args:
        model: a segmentor in eval mode (its ``data_preprocessor`` moves
            the batch to its device).
        pipeline: the config's test pipeline without label loading, built,
            holding a ``LoadSpikeFromFile``.
        source: the recording's path, the ``img_path`` of each window.
    """

    def __init__(self, model, pipeline: Compose, source: str):
        transforms = list(pipeline.transforms)
        self.loader = pipeline_loader(pipeline)
        self.after = transforms[transforms.index(self.loader) + 1:]
        self.model = model
        self.source = source
        self._checked = False

    @torch.no_grad()
    def __call__(self, spikes: torch.Tensor) -> torch.Tensor:
        inputs, samples = [], []
        for window in spikes.to(torch.uint8).cpu().numpy():
            results = self.loader.from_window(dict(img_path=self.source),
                                              window)
            for transform in self.after:
                results = transform(results)
                if results is None:
                    raise ValueError(f'{self.source}: the test pipeline '
                                     f'dropped a window at {transform!r}')
            inputs.append(results['inputs'])
            samples.append(results['data_samples'])
        if not self._checked and inputs:  # once: the windows share a size
            check_input_fits(self.model, *inputs[0].shape, self.source)
            self._checked = True
        predictions = self.model.test_step(dict(inputs=inputs,
                                                data_samples=samples))
        return torch.stack([p.pred_sem_seg.data[0].cpu()
                            for p in predictions])
