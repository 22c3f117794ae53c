"""MMSeg's inferencer for spike files.

``MMSegInferencer`` replaces the test pipeline's ``LoadImageFromFile`` with
its image loader and draws each input read as an image; a spike config has
neither. :class:`SpikeSegInferencer` keeps the config's ``LoadSpikeFromFile``
and draws each stream as an exposure-normalised TFP image, with everything
else (batching, ``return_datasamples``, ``out_dir``, ``show``) MMSeg's::

    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # set-up, before MMSeg is imported
    from wgse_mmseg.apis.inferencer import SpikeSegInferencer
    inferencer = SpikeSegInferencer('configs/pspnet_wgse.py', 'epoch_100.pth')
    result = inferencer('clip.dat', out_dir='vis/')   # or a list, a folder

``mmseg.apis.inference_model(model, 'clip.dat')`` works as it is.
"""
from ..openmmlab_stack import check_mmseg_layer

check_mmseg_layer('wgse_mmseg.apis.inferencer')  # before MMSeg is imported

import os.path as osp
from typing import List, Optional

import numpy as np
from mmcv.transforms import Compose

from mmseg.apis import MMSegInferencer
from ..engine.visualization_hook import spike_clip_image

__all__ = ['SpikeSegInferencer']


def _as_results(spike_file) -> dict:
    """The pipeline's first step: a spike file path -> ``{'img_path'}``."""
    if not isinstance(spike_file, str):
        raise TypeError(f'SpikeSegInferencer takes spike file paths, got '
                        f'{type(spike_file).__name__}')
    return dict(img_path=spike_file)


class SpikeSegInferencer(MMSegInferencer):
    """:class:`mmseg.apis.MMSegInferencer` for spike streams (paths to
    ``.dat``, ``.spk``, ``.npy`` or ``.npz`` files, or folders of them).

    Args: as ``MMSegInferencer`` (``model``: a config path or ``Config``;
    ``weights``: a checkpoint). ``model`` is required: mmengine would
    otherwise execute the config text the checkpoint carries
    (``Config.fromstring`` of ``meta['cfg']``), and a checkpoint is data.
    """

    def _init_model(self, cfg, weights: Optional[str], device: str = 'cpu'):
        if not cfg:  # model=None: the config would come from the weights
            raise ValueError(
                f'SpikeSegInferencer needs a config (model=...); the config '
                f'text in the checkpoint {weights} is data and is not '
                f'executed')
        return super()._init_model(cfg, weights, device)

    def _init_pipeline(self, cfg) -> Compose:
        pipeline = [step for step in cfg.test_dataloader.dataset.pipeline
                    if step['type'] not in ('LoadAnnotations',
                                            'LoadDepthAnnotation')]
        index = self._get_transform_idx(pipeline, 'LoadSpikeFromFile')
        if index == -1:
            raise ValueError('SpikeSegInferencer needs LoadSpikeFromFile in '
                             'the test pipeline; is it a spike config?')
        self.num_steps = cfg.get('num_steps')
        # the drawing reads each stream as the pipeline does
        self.layout = pipeline[index].get('layout')
        return Compose([_as_results] + pipeline)

    def visualize(self, inputs: list, preds: List[dict],
                  return_vis: bool = False, show: bool = False,
                  wait_time: int = 0, img_out_dir: str = '',
                  opacity: float = 0.8,
                  with_labels: Optional[bool] = True
                  ) -> Optional[List[np.ndarray]]:
        """Each prediction over its stream drawn as a TFP image; the files
        in ``img_out_dir`` are named ``<stream name>.png``."""
        if not show and img_out_dir == '' and not return_vis:
            return None
        if self.visualizer is None:
            raise ValueError('visualisation needs a visualizer in the '
                             'config')
        self.visualizer.set_dataset_meta(**self.model.dataset_meta)
        self.visualizer.alpha = opacity
        results = []
        for spike_file, pred in zip(inputs, preds):
            name = f'{osp.splitext(osp.basename(spike_file))[0]}.png'
            self.visualizer.add_datasample(
                name, spike_clip_image(spike_file, self.num_steps,
                                       layout=self.layout), pred,
                show=show, wait_time=wait_time, draw_gt=False,
                draw_pred=True, with_labels=with_labels,
                out_file=osp.join(img_out_dir, name) if img_out_dir else None)
            if return_vis:
                results.append(self.visualizer.get_image())
            self.num_visualized_imgs += 1
        return results if return_vis else None
