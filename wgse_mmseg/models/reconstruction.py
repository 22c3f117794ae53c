"""Image reconstruction from spikes: an enhancer (WGSE) and a residual CNN.

The paper's reconstruction network (Zhang et al., AAAI 2023, Sec. 4.3):
WGSE maps the spike window ``(B, T, H, W)`` to ``(B, T, H, W)``; then a
3x3 convolution to ``channels`` (256), ReLU, ``num_blocks`` (3) residual
blocks without normalisation, a 3x3 convolution to ``mid_channels`` (64),
ReLU, and a 3x3 convolution to one grey channel. Trained with L1 loss.

The last convolution is linear (the public reference ends in a ReLU); a
linear output cannot die at initialisation, and predictions are clipped to
[0, 1]. The ablations of the paper's Table 5 are configs: no enhancer
(residual blocks alone), ``WGSE(wavelet=None)`` (TRCNN without wavelets) and
``WGSE(num_blocks=2)`` (long WGSE).
"""
import os.path as osp
from typing import Any, Callable, Dict, List, Optional, Tuple, Union

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
from mmengine.model import BaseModel, ImgDataPreprocessor
from mmengine.structures import BaseDataElement, PixelData

from mmseg.registry import MODELS
from ..argument_checks import (ArgumentError, check_integer,
                               check_parameter_count, check_path)
from ..core.checks import check_device, check_finite
from ..fileio.atomic import atomic_output
from ..core import reconstruction_baselines
from ..core.constants import RECONSTRUCTION_METHODS
from ..utils.checkpoint import CheckpointError, read_checkpoint
from ..utils.config_data import ConfigDataError, read_config_data
from ..utils.safe_build import build_from_file_config, check_file_config
from .enhancers import ENHANCERS

__all__ = ['SpikeReconstructor', 'load_reconstructor', 'export_weights']

#: Weights shipped with the package (see docs/reconstruction.md).
DEFAULT_WEIGHTS = osp.join(osp.dirname(osp.dirname(osp.abspath(__file__))),
                           'weights', 'wgse_reconstruction_cpu.pth')

#: The classical reconstructions by name
#: (:mod:`wgse_mmseg.core.reconstruction_baselines`, REDS scale).
CLASSICAL_METHODS = {name: getattr(reconstruction_baselines, name)
                     for name in RECONSTRUCTION_METHODS if name != 'wgse'}
#: Names accepted by :func:`reconstruction_method` (the one list:
#: :data:`~wgse_mmseg.core.constants.RECONSTRUCTION_METHODS`).
METHODS = RECONSTRUCTION_METHODS


def _conv3x3(in_channels: int, out_channels: int) -> nn.Conv2d:
    return nn.Conv2d(in_channels, out_channels, 3, padding=1)


def _conv3x3_parameters(in_channels: int, out_channels: int) -> int:
    """Weights and biases of :func:`_conv3x3`."""
    return (9 * in_channels + 1) * out_channels


class ResidualBlock(nn.Module):
    """``x + conv(relu(conv(x)))``, 3x3 convolutions, no normalisation.
    A part of :class:`SpikeReconstructor`, which checks ``channels``."""

    def __init__(self, channels: int):
        super().__init__()
        self.conv1 = _conv3x3(channels, channels)
        self.conv2 = _conv3x3(channels, channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv2(F.relu(self.conv1(x)))


@MODELS.register_module()
class SpikeReconstructor(BaseModel):
    """Spike window ``(B, T, H, W)`` -> grey image ``(B, 1, H, W)``.

    Args:
        num_steps: ``T``, frames per window (41 in the literature); batches
            with another ``T`` are refused naming both numbers.
        enhancer: config of a module ``(B, T, H, W) -> (B, T, H, W)``
            (``dict(type='WGSE')``); ``None`` feeds the raw spikes.
        channels: width of the residual blocks (256 in the paper).
        num_blocks: residual blocks (3 in the paper).
        mid_channels: width of the penultimate convolution (64).
        data_preprocessor: batches the packed ``(T, H, W)`` uint8 inputs
            into float ``(B, T, H, W)``; mmengine's ``ImgDataPreprocessor``
            without normalisation by default.
        init_cfg: mmengine initialisation config.

    Inputs holding NaN or Inf are refused (``ValueError``), as by every
    enhancer.

    ``forward(inputs, data_samples, mode)``: ``'tensor'`` returns the raw
    ``(B, 1, H, W)`` output; ``'loss'`` the L1 loss against the samples'
    ``gt_image`` ``(1, H, W)``; ``'predict'`` the data samples with
    ``pred_image`` ``(1, H, W)`` clipped to [0, 1].
    """

    def __init__(self, num_steps: int = 41,
                 enhancer: Optional[dict] = dict(type='WGSE'),
                 channels: int = 256, num_blocks: int = 3,
                 mid_channels: int = 64,
                 data_preprocessor: Optional[dict] = None,
                 init_cfg: Optional[dict] = None):
        entry = 'SpikeReconstructor'
        check_integer(entry, 'num_steps', num_steps, 1)
        if enhancer is not None and not isinstance(enhancer, dict):
            raise ArgumentError(entry, 'enhancer', "a model config (a dict "
                                "with 'type') or None", enhancer)
        check_integer(entry, 'channels', channels, 1)
        check_integer(entry, 'num_blocks', num_blocks, 0)
        check_integer(entry, 'mid_channels', mid_channels, 1)
        super().__init__(
            data_preprocessor=data_preprocessor or dict(
                type='ImgDataPreprocessor'),
            init_cfg=init_cfg)
        check_parameter_count(
            'SpikeReconstructor',
            _conv3x3_parameters(num_steps, channels) +
            2 * num_blocks * _conv3x3_parameters(channels, channels) +
            _conv3x3_parameters(channels, mid_channels) +
            _conv3x3_parameters(mid_channels, 1),
            'num_steps, channels, num_blocks and mid_channels')
        self.num_steps = num_steps
        self.enhancer = MODELS.build(enhancer) if enhancer else None
        self.head = nn.Sequential(
            _conv3x3(num_steps, channels), nn.ReLU(inplace=True),
            *[ResidualBlock(channels) for _ in range(num_blocks)],
            _conv3x3(channels, mid_channels), nn.ReLU(inplace=True),
            _conv3x3(mid_channels, 1))

    def _forward(self, inputs: torch.Tensor) -> torch.Tensor:
        if inputs.dim() != 4 or inputs.shape[1] != self.num_steps:
            raise ValueError(
                f'SpikeReconstructor is built for (B, T={self.num_steps}, H, '
                f'W) spike windows, got {tuple(inputs.shape)}; set num_steps '
                f'in the config to the window length')
        check_finite('SpikeReconstructor', 'inputs', inputs)
        features = self.enhancer(inputs) if self.enhancer else inputs
        return self.head(features)

    def forward(self, inputs: torch.Tensor,
                data_samples: Optional[List[BaseDataElement]] = None,
                mode: str = 'tensor'
                ) -> Union[torch.Tensor, Dict[str, torch.Tensor],
                           List[BaseDataElement]]:
        out = self._forward(inputs)
        if mode == 'tensor':
            return out
        if mode == 'loss':
            if not data_samples or any('gt_image' not in s
                                       for s in data_samples):
                raise ValueError('mode="loss" needs data samples with '
                                 'gt_image')
            gt = torch.stack([s.gt_image.data for s in data_samples]).to(out)
            return dict(loss_l1=F.l1_loss(out, gt))
        if mode == 'predict':
            if data_samples is None:
                data_samples = [BaseDataElement() for _ in range(len(out))]
            for sample, image in zip(data_samples, out.clamp(0, 1)):
                sample.pred_image = PixelData(data=image)
            return data_samples
        raise ValueError(f'mode must be "tensor", "loss" or "predict", got '
                         f'{mode!r}')

    def reconstruct(self, spikes: np.ndarray) -> np.ndarray:
        """One window ``(T, H, W)`` of 0/1 -> ``(H, W)`` float in [0, 1]."""
        windows = torch.as_tensor(np.asarray(spikes),
                                  dtype=next(self.parameters()).dtype)
        return self.reconstruct_windows(windows[None])[0].numpy()

    @torch.no_grad()
    def reconstruct_windows(self, spikes: torch.Tensor) -> torch.Tensor:
        """Windows ``(B, T, H, W)`` of 0/1 (any device) -> ``(B, H, W)``
        float images in [0, 1] on the CPU, one model call."""
        param = next(self.parameters())
        inputs = spikes.to(dtype=param.dtype, device=param.device)
        return self._forward(inputs)[:, 0].clamp(0, 1).cpu()


#: what a checkpoint's model config may build (checked at every depth by
#: :mod:`wgse_mmseg.utils.safe_build`): the reconstruction model, with one of
#: the registered enhancers (or none) in front and mmengine's
#: ``ImgDataPreprocessor`` (its default) batching the inputs
RECONSTRUCTION_BUILDS = {
    SpikeReconstructor: dict(
        enhancer={enhancer: {} for enhancer in ENHANCERS},
        data_preprocessor={ImgDataPreprocessor: {}}),
}


def _model_config(checkpoint: dict, path: str) -> Tuple[Any, str]:
    """The checkpoint's model config, as read (unchecked), and where in the
    file it lies (for errors)."""
    meta = checkpoint.get('meta') or {}
    if not isinstance(meta, dict):
        raise ConfigDataError(f'{path}: meta is a {type(meta).__name__}, '
                              f'not a dict')
    if 'model' in meta:  # exported by export_weights
        config, where = meta['model'], "meta['model']"
    elif 'cfg' in meta:  # an mmengine Runner checkpoint
        config = read_config_data(meta['cfg'], f'{path} (meta["cfg"])').get(
            'model')
        where = "meta['cfg'] model"
    else:
        raise ValueError(
            f'{path}: holds no model config (neither meta["model"] of '
            f'export_weights nor meta["cfg"] of an mmengine checkpoint)')
    return config, where


def _read_weights(path: str) -> dict:
    """A checkpoint that holds a ``state_dict`` (mmengine's or exported)."""
    state = read_checkpoint(path)
    if not isinstance(state.get('state_dict'), dict):
        raise CheckpointError(f'{path}: no state_dict in the checkpoint '
                              f'(keys: {sorted(map(str, state))[:10]})')
    return state


def load_reconstructor(checkpoint: Optional[str] = None,
                       device: str = 'cpu') -> SpikeReconstructor:
    """A trained :class:`SpikeReconstructor` in eval mode.

    Args:
        checkpoint: an mmengine checkpoint of a reconstruction config
            (``work_dirs/.../iter_N.pth``) or a file written by
            :func:`export_weights`; ``None`` for the shipped weights
            (``wgse_mmseg/weights/wgse_reconstruction_cpu.pth``).
        device: torch device.
    """
    check_path('load_reconstructor', 'checkpoint', checkpoint, optional=True)
    device = check_device('load_reconstructor', 'device', device)
    path = checkpoint or DEFAULT_WEIGHTS
    state = _read_weights(path)
    config, key = _model_config(state, path)
    model = build_from_file_config(MODELS, config, RECONSTRUCTION_BUILDS,
                                   path, key)
    try:
        model.load_state_dict(state['state_dict'], strict=True)
    except RuntimeError as err:
        raise ValueError(f'{path}: weights do not fit the model of its own '
                         f'config: {err}') from err
    return model.to(device).eval()


def export_weights(checkpoint: str, out: str) -> None:
    """Write the weights and model config of a Runner checkpoint to ``out``.

    The result (``{'state_dict', 'meta': {'model', 'source'}}``, no
    optimiser state or logs) is what :func:`load_reconstructor` and
    ``tools/misc/reconstruct.py`` read; about 4 bytes per parameter.
    """
    check_path('export_weights', 'checkpoint', checkpoint)
    check_path('export_weights', 'out', out)
    state = _read_weights(checkpoint)
    config, key = _model_config(state, checkpoint)
    model_cfg = check_file_config(config, RECONSTRUCTION_BUILDS, checkpoint,
                                  key)
    exported = dict(state_dict=state['state_dict'],
                    meta=dict(model=model_cfg,
                              source=osp.basename(checkpoint)))
    with atomic_output(out) as f:
        torch.save(exported, f)


def reconstruction_method(method: str, checkpoint: Optional[str] = None,
                          device: str = 'cpu'
                          ) -> Callable[[np.ndarray], np.ndarray]:
    """A function ``(T, H, W)`` spike window -> ``(H, W)`` image in [0, 1].

    ``method``: ``'wgse'`` (the trained model of ``checkpoint``, by default
    the shipped weights) or one of :data:`CLASSICAL_METHODS` (REDS scale,
    see :mod:`wgse_mmseg.core.reconstruction_baselines`).
    """
    if method == 'wgse':
        return load_reconstructor(checkpoint, device).reconstruct
    if method in CLASSICAL_METHODS:
        return CLASSICAL_METHODS[method]
    raise ValueError(f'unknown method {method!r}; expected one of {METHODS}')
