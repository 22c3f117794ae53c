"""PSNR, SSIM and 2-D entropy of reconstructed images as an mmengine metric."""
from typing import Dict, List, Sequence

import numpy as np
from mmengine.evaluator import BaseMetric

from mmseg.registry import METRICS
from .image_quality import entropy_2d, psnr, ssim

__all__ = ['ReconstructionMetric']


def _image(field) -> np.ndarray:
    """``PixelData`` (or its dict) ``(1, H, W)`` -> ``(H, W)`` array."""
    data = field['data'] if isinstance(field, dict) else field.data
    return data.detach().cpu().numpy().reshape(data.shape[-2:])


@METRICS.register_module()
class ReconstructionMetric(BaseMetric):
    """Image reconstruction quality, averaged over images.

    Reads ``pred_image`` (and ``gt_image`` when present) of each data sample,
    ``PixelData`` of shape ``(1, H, W)`` in [0, 1] (see
    :class:`~wgse_mmseg.models.reconstruction.SpikeReconstructor`).

    Returns ``PSNR`` (dB) and ``SSIM`` over the samples with ground truth
    (:func:`~wgse_mmseg.evaluation.psnr`,
    :func:`~wgse_mmseg.evaluation.ssim`), and ``Entropy2D``
    (bits, no reference) over all samples. A set without ground truth gives
    ``Entropy2D`` alone.
    """
    default_prefix = None

    def process(self, data_batch, data_samples: Sequence[dict]) -> None:
        for sample in data_samples:
            pred = np.clip(_image(sample['pred_image']), 0, 1)
            record = dict(entropy=entropy_2d(pred))
            if 'gt_image' in sample:
                gt = _image(sample['gt_image'])
                record.update(psnr=psnr(pred, gt), ssim=ssim(pred, gt))
            self.results.append(record)

    def compute_metrics(self, results: List[dict]) -> Dict[str, float]:
        metrics = dict(Entropy2D=float(np.mean([r['entropy']
                                                for r in results])))
        scored = [r for r in results if 'psnr' in r]
        if scored:
            metrics['PSNR'] = float(np.mean([r['psnr'] for r in scored]))
            metrics['SSIM'] = float(np.mean([r['ssim'] for r in scored]))
        return metrics
