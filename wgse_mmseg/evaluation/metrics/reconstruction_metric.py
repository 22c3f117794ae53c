"""PSNR, SSIM and 2-D entropy of reconstructed images as an mmengine metric."""
from typing import Dict, List, Sequence

import numpy as np
from mmengine.evaluator import BaseMetric

from mmseg.registry import METRICS
from .image_quality import entropy_2d, psnr, ssim

__all__ = ['ReconstructionMetric']


def _image(field, name: str, where: str) -> np.ndarray:
    """``PixelData`` (or its dict) ``(1, H, W)`` or ``(H, W)`` -> ``(H, W)``
    float array; anything else, or NaN or Inf, is a ``ValueError`` naming
    ``where`` (the sample), the field ``name`` and the shape expected."""
    data = field['data'] if isinstance(field, dict) else field.data
    shape = tuple(data.shape)
    if len(shape) not in (2, 3) or (len(shape) == 3 and shape[0] != 1) \
            or 0 in shape:
        raise ValueError(
            f'ReconstructionMetric: {where}: {name} is shaped {shape}; '
            f'expected one grey image, (1, H, W) or (H, W) with H, W >= 1')
    image = data.detach().cpu().numpy().reshape(shape[-2:])
    if not np.isfinite(image).all():
        raise ValueError(
            f'ReconstructionMetric: {where}: {name} holds '
            f'{int((~np.isfinite(image)).sum())} non-finite value(s)')
    return image


def _sample_name(sample, index: int) -> str:
    """``sample index`` of the batch, with its file where it has one."""
    paths = [sample[key] for key in ('img_path', 'gt_path')
             if isinstance(sample, dict) and sample.get(key)]
    return f'sample {index}' + (f' ({paths[0]})' if paths else '')


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
        """Score each of ``data_samples``; a prediction or ground truth
        that is not one grey image, or a pair of different sizes, is a
        ``ValueError`` naming the sample (its index in the batch and its
        file) and the shape expected."""
        for index, sample in enumerate(data_samples):
            where = _sample_name(sample, index)
            pred = np.clip(_image(sample['pred_image'], 'pred_image', where),
                           0, 1)
            record = dict(entropy=entropy_2d(pred))
            if 'gt_image' in sample:
                gt = _image(sample['gt_image'], 'gt_image', where)
                if gt.shape != pred.shape:
                    raise ValueError(
                        f'ReconstructionMetric: {where}: pred_image is '
                        f'{pred.shape[0]}x{pred.shape[1]} but gt_image is '
                        f'{gt.shape[0]}x{gt.shape[1]}; expected the same '
                        f'size')
                try:
                    record.update(psnr=psnr(pred, gt), ssim=ssim(pred, gt))
                except ValueError as error:
                    raise ValueError(
                        f'ReconstructionMetric: {where}: {error}') from error
            self.results.append(record)

    def compute_metrics(self, results: List[dict]) -> Dict[str, float]:
        metrics = dict(Entropy2D=float(np.mean([r['entropy']
                                                for r in results])))
        scored = [r for r in results if 'psnr' in r]
        if scored:
            metrics['PSNR'] = float(np.mean([r['psnr'] for r in scored]))
            metrics['SSIM'] = float(np.mean([r['ssim'] for r in scored]))
        return metrics
