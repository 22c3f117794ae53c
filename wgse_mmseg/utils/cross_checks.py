"""The cross-field checks a training run makes at its start, before any
data is read: values that are each in their declared range but do not fit
together or do not fit the model are refused, naming the smallest value
that works.

Which input sizes a model takes and which batch its batch norms need are
properties of the built model (its strides, kernels, pooling and norm
layers), so they are measured on it, not listed per architecture: a dry
forward of zero spikes ``(B, T, h, w)`` through the data preprocessor's
enhancer and the model (``mode='tensor'``), without gradients, with the
random number generators and the batch-norm statistics left as they were.

* the crop (the preprocessor's ``size``, ``crop_size``) against the
  smallest input side the model takes (:func:`smallest_input_side`);
* a batch of one window against batch norms that then see one value per
  channel (a pooled 1x1 branch: PSPNet's, DeepLabV3's): the smallest batch
  that works.

:class:`~wgse_mmseg.engine.SpikeRunner` runs :func:`check_training_fits`
when training starts, so every entry point (``tools/train.py``, MMSeg's,
``mim train``) has it.
"""
import contextlib
from typing import Callable, Iterator, Optional, Tuple

import torch
from torch import nn

from ..core.limits import MAX_IMAGE_SIDE, cut

__all__ = ['ModelFitError']

#: the side the dry forward is capped at: a crop whose sides reach it is
#: checked at it (a model that takes an input takes every larger one)
PROBE_SIDE = 64


class ModelFitError(ValueError):
    """Settings that are each valid but do not fit the model or each
    other; names the setting and the smallest value that works."""


@contextlib.contextmanager
def _untouched(model: nn.Module, training: bool) -> Iterator[None]:
    """``model`` in train or eval mode for a dry forward, and as it was
    afterwards: its mode, its buffers (batch-norm statistics) and torch's
    random number generators."""
    modes = {module: module.training for module in model.modules()}
    buffers = [(b, b.detach().clone()) for b in model.buffers()]
    devices = sorted({p.device.index or 0 for p in model.parameters()
                      if p.device.type == 'cuda'})
    with torch.random.fork_rng(devices=devices), torch.no_grad():
        try:
            model.train(training)
            yield
        finally:
            for module, mode in modes.items():
                module.training = mode
            for buffer, saved in buffers:
                buffer.copy_(saved)


def _dry_forward(model: nn.Module, num_steps: int, batch: int, height: int,
                 width: int, training: bool) -> Optional[Exception]:
    """``None`` where ``model`` runs zero spikes ``(batch, num_steps,
    height, width)``, else the error it raised."""
    device = next(model.parameters(), torch.empty(0)).device
    spikes = torch.zeros(batch, num_steps, height, width, device=device)
    with _untouched(model, training):
        try:
            enhancer = getattr(model.data_preprocessor, 'enhancer', None)
            model(spikes if enhancer is None else enhancer(spikes), None,
                  mode='tensor')
        except (RuntimeError, ValueError, AssertionError, IndexError) as err:
            return err
    return None


def smallest_input_side(runs: Callable[[int], bool],
                        start: int) -> Optional[int]:
    """The smallest side ``s`` for which ``runs(s)``, searched up from
    ``start`` (doubling, then halving the gap), on the premise that a model
    that takes an input takes every larger one; ``None`` if none up to
    :data:`~wgse_mmseg.core.limits.MAX_IMAGE_SIDE` does."""
    low, high = 0, max(1, start)  # runs(low) is False (or low is 0)
    while not runs(high):
        if high >= MAX_IMAGE_SIDE:
            return None
        low, high = high, min(2 * high, MAX_IMAGE_SIDE)
    while high - low > 1:
        middle = (low + high) // 2
        if runs(middle):
            high = middle
        else:
            low = middle
    return high


def _smallest_side(model: nn.Module, num_steps: int,
                   probe: Tuple[int, int], source: str) -> Optional[int]:
    """``None`` where ``model`` runs a ``probe``-sized input; else the
    smallest side it takes (:func:`smallest_input_side`).

    Raises:
        ModelFitError: naming ``source``, where it runs on no input.
    """
    failure = _dry_forward(model, num_steps, 1, *probe, training=False)
    if failure is None:
        return None
    side = smallest_input_side(lambda s: _dry_forward(
        model, num_steps, 1, s, s, training=False) is None, min(probe))
    if side is None:
        raise ModelFitError(
            f'{source}: the model runs on no input up to {MAX_IMAGE_SIDE}x'
            f'{MAX_IMAGE_SIDE} (num_steps={num_steps}): '
            f'{type(failure).__name__}: {cut(str(failure), 300)}')
    return side


def check_input_fits(model: nn.Module, num_steps: int, height: int,
                     width: int, source: str) -> None:
    """Refuse, before inference, a ``(num_steps, height, width)`` input
    (after the test pipeline) smaller than the smallest input ``model``
    takes, as :func:`check_training_fits` refuses a crop: a dry forward
    at the size the data preprocessor pads it to (its ``size_divisor``),
    capped at :data:`PROBE_SIDE`; where it fails, the smallest side that
    works is searched.

    Raises:
        ModelFitError: naming ``source``, its size and the smallest side.
    """
    model = getattr(model, 'module', model)
    divisor = getattr(model.data_preprocessor, 'size_divisor', None) or 1
    padded = [-(-side // divisor) * divisor for side in (height, width)]
    probe = tuple(min(side, PROBE_SIDE) for side in padded)
    side = _smallest_side(model, num_steps, probe, source)
    if side is None or min(padded) >= side:
        return
    raise ModelFitError(
        f'{source}: frames of {height}x{width} are below the smallest input '
        f"the model takes, {side}x{side} (its backbone's strides and "
        f'kernels); give a larger recording, or a test pipeline that '
        f'resizes it')


def _crop(cfg, model: nn.Module) -> Optional[Tuple[int, int]]:
    size = getattr(model.data_preprocessor, 'size', None) or cfg.get(
        'crop_size')
    return None if size is None else (int(size[0]), int(size[1]))


def check_training_fits(cfg, model: nn.Module) -> None:
    """Refuse a training config whose crop or batch does not fit its built
    ``model`` (see the module docstring); nothing is done otherwise.

    Raises:
        ModelFitError: naming the setting (``crop_size``,
            ``train_dataloader.batch_size``), the model's config and the
            smallest value that works.
    """
    model = getattr(model, 'module', model)  # DistributedDataParallel
    num_steps = cfg.get('num_steps') or getattr(
        model.data_preprocessor, 'num_steps', None)
    crop = _crop(cfg, model)
    if num_steps is None or crop is None:
        return
    name = getattr(cfg, 'filename', None) or 'the config'
    probe = tuple(min(side, PROBE_SIDE) for side in crop)
    side = _smallest_side(model, num_steps, probe, name)
    if side is not None and min(crop) < side:
        raise ModelFitError(
            f'{name}: crop_size={crop} is below the smallest input the '
            f"model takes, {side}x{side} (its backbone's strides and "
            f'kernels); set --cfg-options crop_size={max(crop[0], side)},'
            f'{max(crop[1], side)} or larger')
    batch = cfg.get('train_dataloader', {}).get('batch_size')
    if batch == 1:
        failure = _dry_forward(model, num_steps, 1, *probe, training=True)
        if failure is not None and _dry_forward(
                model, num_steps, 2, *probe, training=True) is None:
            raise ModelFitError(
                f'{name}: train_dataloader.batch_size=1 does not train this '
                f'model: {cut(str(failure), 200)} (a batch norm after a '
                f'pooled 1x1 branch sees one value per channel); the smallest '
                f'batch_size that works is 2')
