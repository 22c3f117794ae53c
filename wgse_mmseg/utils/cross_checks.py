"""The cross-field checks a spike model makes before it trains or infers,
before any data is read: values that are each in their declared range but
do not fit together or do not fit the model are refused, naming the field
to change and the smallest value that works.

What a model takes is a property of the built model (its first layer's
width, its strides, kernels, pooling and norm layers), so it is read off
the built model, not listed per architecture, by a forward of shapes only:
the model runs on meta tensors, or where one of its operations has no meta
form, on fake tensors (torch's ``FakeTensorMode``), and every operation
computes its output's shape, none its values, so a check at any input size
allocates nothing. The enhancer runs once
for real on a tiny input, for the number of channels it gives the model.
Where a model uses an operation that has no shape-only form (one that
reads a tensor's values), the check runs it for real once, at most
:data:`PROBE_SIDE` pixels a side, and searches no further.

* every convolution's input width: the first layer that is given another
  number of channels than it takes is named with the field that sets it
  (a stem left at an RGB base's 3 channels, say), before anything else;
* the heads' class count against the data's (the data preprocessor's
  ``num_classes``);
* the crop (the preprocessor's ``size``, ``crop_size``) and an inference
  input against the smallest input side the model takes;
* a batch of one window against batch norms that then see one value per
  channel (a pooled 1x1 branch: PSPNet's, DeepLabV3's): the smallest batch
  that works.

:class:`~wgse_mmseg.engine.SpikeRunner` runs :func:`check_training_fits`
when training starts and :func:`check_model_fits` when it tests, so every
entry point (``tools/train.py``, ``tools/test.py``, MMSeg's, ``mim``) has
them; the demo, the recording walk and the ONNX export run
:func:`check_input_fits`.
"""
import contextlib
import warnings
from typing import Callable, Iterator, Optional, Tuple

import torch
from torch import nn
from torch._subclasses import fake_tensor

from ..limits import MAX_IMAGE_SIDE
from ..errors import WgseError, cut

__all__ = ['ModelFitError']

#: the largest side a forward of real tensors is run at, where a model has
#: an operation without a shape-only form
PROBE_SIDE = 64
#: what torch raises where an operation cannot run on fake tensors
_NO_SHAPE_ONLY_FORM = tuple(getattr(fake_tensor, name) for name in (
    'DataDependentOutputException', 'DynamicOutputShapeException',
    'UnsupportedOperatorException', 'UnsupportedFakeTensorException',
    'UnsupportedMutationAliasingException') if hasattr(fake_tensor, name))
#: what a model raises for an input it does not take
_REFUSALS = (RuntimeError, ValueError, AssertionError, IndexError)


class ModelFitError(WgseError, ValueError):
    """Settings that are each valid but do not fit the model or each
    other; names the setting and the smallest value that works."""


class _WrongWidth(WgseError, ValueError):
    """A layer given another number of channels than it takes."""

    def __init__(self, name: str, layer: nn.Module, given: int):
        super().__init__(name)
        self.name, self.layer, self.given = name, layer, given


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


@contextlib.contextmanager
def _on_meta(model: nn.Module) -> Iterator[None]:
    """``model`` with every parameter and buffer a meta tensor of its
    shape and dtype (one for a tensor that several modules share), and its
    own tensors again afterwards."""
    meta = {}
    swapped = []
    try:
        for module in model.modules():
            for table in (module._parameters, module._buffers):
                for name, tensor in table.items():
                    if tensor is None:
                        continue
                    if id(tensor) not in meta:
                        empty = torch.empty_like(tensor, device='meta')
                        meta[id(tensor)] = nn.Parameter(
                            empty, tensor.requires_grad) if isinstance(
                                tensor, nn.Parameter) else empty
                    swapped.append((table, name, tensor))
                    table[name] = meta[id(tensor)]
        yield
    finally:
        for table, name, tensor in swapped:
            table[name] = tensor


@contextlib.contextmanager
def _widths_checked(model: nn.Module) -> Iterator[None]:
    """Every convolution of ``model`` raises :class:`_WrongWidth` when it is
    given another number of channels than it takes, before it runs."""
    def check(name):
        def hook(layer, args):
            given = args[0].shape[1] if args and isinstance(
                args[0], torch.Tensor) and args[0].dim() > 1 else None
            if given is not None and given != layer.in_channels:
                raise _WrongWidth(name, layer, given)
        return hook
    handles = [module.register_forward_pre_hook(check(name))
               for name, module in model.named_modules()
               if isinstance(module, nn.modules.conv._ConvNd)]
    try:
        yield
    finally:
        for handle in handles:
            handle.remove()


class _Probe:
    """Dry forwards of zero spikes through a built segmentor
    (``mode='tensor'``), on shapes only where the model allows it."""

    def __init__(self, model: nn.Module, num_steps: int, source: str,
                 stem_hint: str = ''):
        self.model = getattr(model, 'module', model)  # DistributedDataParallel
        self.num_steps, self.source, self.stem_hint = (num_steps, source,
                                                       stem_hint)
        self.device = next(self.model.parameters(), torch.empty(0)).device
        self.shapes_only = True
        self.unjudged: Optional[Exception] = None
        self.channels = self._enhanced_channels()

    def _enhanced_channels(self) -> int:
        """The channels the enhancer gives the model for ``num_steps``
        (``num_steps`` itself without one)."""
        enhancer = getattr(self.model.data_preprocessor, 'enhancer', None)
        if enhancer is None:
            return self.num_steps
        spikes = torch.zeros(1, self.num_steps, 8, 8, device=self.device)
        with _untouched(enhancer, False):
            return enhancer(spikes).shape[1]

    def _wrong_width(self, wrong: _WrongWidth) -> ModelFitError:
        layer = wrong.layer
        what = (f"the spikes' {wrong.given} channels (num_steps="
                f'{self.num_steps})' if wrong.given == self.channels else
                f'{wrong.given} channels')
        fix = self.stem_hint or 'set the in_channels of what builds it'
        return ModelFitError(
            f"{self.source}: the model's layer {wrong.name} "
            f'({type(layer).__name__}) takes {layer.in_channels} input '
            f'channels but is given {what}; {fix}')

    def error(self, batch: int, height: int, width: int,
              training: bool) -> Optional[Exception]:
        """``None`` where the model runs ``(batch, T, height, width)``, else
        what it raised; a layer of the wrong width raises
        :class:`ModelFitError` at once."""
        if self.shapes_only:
            try:
                return self._run(batch, height, width, training, True)
            except _NO_SHAPE_ONLY_FORM:
                self.shapes_only = False
        return self._run(batch, min(height, PROBE_SIDE),
                         min(width, PROBE_SIDE), training, False)

    def _run(self, batch, height, width, training, shapes_only):
        shape = (batch, self.channels, height, width)
        with _untouched(self.model, training), \
                _widths_checked(self.model):
            try:
                if shapes_only:
                    self._forward_on_shapes(shape)
                else:
                    self.model(torch.zeros(shape, device=self.device), None,
                               mode='tensor')
            except _WrongWidth as wrong:
                raise self._wrong_width(wrong) from None
            except _NO_SHAPE_ONLY_FORM:
                raise
            except _REFUSALS as err:
                return err
            except Exception as err:  # a forward mode='tensor' cannot run
                # (MMSeg's PointRend: its point head needs the training
                # step's inputs): no verdict on sizes, said once
                if self.unjudged is None:
                    self.unjudged = err
                    warnings.warn(
                        f'{self.source}: the start-up check cannot run the '
                        f"model's tensor forward ({type(err).__name__}: "
                        f'{cut(str(err), 120)}): its input sizes and batch '
                        f'are not checked')
        return None

    def _forward_on_shapes(self, shape: Tuple[int, int, int, int]) -> None:
        """The forward of an input of ``shape`` ``(B, C, H, W)`` on
        shapes only: first on meta tensors (the parameters and buffers
        swapped for meta ones; torch's compiled shape functions, several
        times quicker than fake tensors); where that raises, on fake
        tensors, whose verdict stands (they also take what a meta forward
        cannot: tensors the model makes on its own device as it runs)."""
        try:
            with _on_meta(self.model):
                self.model(torch.zeros(shape, device='meta'), None,
                           mode='tensor')
            return
        except _WrongWidth:
            raise
        except Exception:  # judged on fake tensors below
            pass
        with fake_tensor.FakeTensorMode(allow_non_fake_inputs=True):
            self.model(torch.zeros(shape, device=self.device), None,
                       mode='tensor')

    def _fixed_size(self) -> Optional[Tuple[int, int]]:
        """The ``img_size`` of a backbone that runs only at it (a vision
        transformer with fixed position embeddings), else ``None``."""
        for module in self.model.modules():
            size = getattr(module, 'img_size', None)
            if isinstance(size, int):
                size = (size, size)
            if isinstance(size, (tuple, list)) and len(size) == 2 and all(
                    isinstance(v, int) and v > 0 for v in size) and \
                    self.error(1, *size, training=False) is None:
                return tuple(size)
        return None

    def smallest_side(self, probe: Tuple[int, int]) -> Optional[int]:
        """``None`` where the model runs a ``probe``-sized input; else the
        smallest side it takes (:func:`smallest_input_side`, over shapes
        only).

        Raises:
            ModelFitError: naming the source, where the model runs on no
                input (or, where it cannot be run on shapes only, not on
                this one: then nothing larger is tried).
        """
        failure = self.error(1, *probe, training=False)
        if failure is None:
            return None
        side = smallest_input_side(
            lambda s: self.error(1, s, s, training=False) is None,
            min(probe)) if self.shapes_only else None
        fixed = self._fixed_size() if side is None else None
        if fixed is not None:
            raise ModelFitError(
                f'{self.source}: the model takes only its fixed input size '
                f'{fixed[0]}x{fixed[1]} (its backbone\'s img_size, for its '
                f'position embeddings): set crop_size={fixed[0]},'
                f'{fixed[1]}, and a test pipeline that gives that size')
        if side is None:
            reach = (f'on no input up to {MAX_IMAGE_SIDE}x{MAX_IMAGE_SIDE}'
                     if self.shapes_only else
                     f'on a {min(probe[0], PROBE_SIDE)}x'
                     f'{min(probe[1], PROBE_SIDE)} input')
            raise ModelFitError(
                f'{self.source}: the model runs {reach} '
                f'(num_steps={self.num_steps}): '
                f'{type(failure).__name__}: {cut(str(failure), 300)}')
        return side


def smallest_input_side(runs: Callable[[int], bool],
                        start: int) -> Optional[int]:
    """The smallest side ``s`` for which ``runs(s)``, searched up from
    ``start`` (doubling, then halving the gap), on the premise that a model
    that takes an input takes every larger one; ``None`` if none up to
    :data:`~wgse_mmseg.limits.MAX_IMAGE_SIDE` does. The checks call it
    with forwards of shapes only, which allocate nothing at any side."""
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


def _check_classes(model: nn.Module, source: str) -> None:
    """Every head predicts the data's classes (the data preprocessor's
    ``num_classes``, which the dataset base sets)."""
    wanted = getattr(model.data_preprocessor, 'num_classes', None)
    if wanted is None:
        return
    for name, module in model.named_modules():
        classes = getattr(module, 'num_classes', None)
        if not hasattr(module, 'conv_seg') or classes is None or any(
                klass.__name__ in OWN_TARGET_HEADS
                for klass in type(module).__mro__):
            continue  # not one of MMSeg's decode heads
        binary = classes == 2 and getattr(module, 'out_channels', 2) == 1
        if classes != wanted and not (binary and wanted == 2):
            raise ModelFitError(
                f'{source}: model.{name}.num_classes={classes}, but the data '
                f'has {wanted} classes (model.data_preprocessor.num_classes'
                f'); set num_classes={wanted} in model.{name}, e.g. '
                f'{name}=dict(num_classes={{{{_base_.num_classes}}}}) with '
                f'the dataset base')


def check_input_fits(model: nn.Module, num_steps: int, height: int,
                     width: int, source: str) -> None:
    """Refuse, before inference, a ``(num_steps, height, width)`` input
    (after the test pipeline) that ``model`` cannot take: a layer of
    another width than the spikes', heads of another class count than the
    data's, or frames smaller than the smallest input, checked at the size
    the data preprocessor pads them to (its ``size_divisor``).

    Raises:
        ModelFitError: naming ``source``, the field or the size, and what
            works.
    """
    model = getattr(model, 'module', model)
    _check_classes(model, source)
    divisor = getattr(model.data_preprocessor, 'size_divisor', None) or 1
    padded = [-(-side // divisor) * divisor for side in (height, width)]
    side = _Probe(model, num_steps, source).smallest_side(tuple(padded))
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


def _stem_hint(cfg, num_steps: int) -> str:
    """What to set for a layer of the wrong width, from where ``cfg`` sets
    its stem's width."""
    from .spike_settings import takes_in_channels, stem_fields
    stems = stem_fields(cfg)
    if not stems:
        return (f'a spike model needs a SpikeSegDataPreProcessor with '
                f'num_steps={num_steps} and a backbone with in_channels='
                f'{num_steps}')
    fixes = []
    for path, backbone in stems:
        kind = backbone.get('type')
        if backbone.get('in_channels', num_steps) != num_steps or (
                'in_channels' not in backbone and takes_in_channels(kind)):
            fixes.append(f'set {path}.in_channels={num_steps} (or load the '
                         f'config with wgse_mmseg.load_config, which does)')
        elif not takes_in_channels(kind):
            fixes.append(f'{path} ({kind}) has no in_channels argument, so '
                         f'it cannot take spikes: choose a backbone that '
                         f'has one (docs/models.md)')
    named = ', '.join(f'{path} ({backbone.get("type")})'
                      for path, backbone in stems)
    return '; '.join(fixes) or (
        f'{named} has in_channels={num_steps} but does not build this layer '
        f'from it: it cannot take spikes (docs/models.md)')


#: heads that predict targets of their own, not the data's classes
#: (STDC's boundary head: 2 classes, edge or not, whatever the data)
OWN_TARGET_HEADS = ('STDCHead',)


def check_model_fits(cfg, model: nn.Module) -> None:
    """Refuse a config whose built ``model`` cannot take its spikes: a layer
    of another width than T, heads of another class count than the data's
    (for a test run; training also checks the crop and the batch:
    :func:`check_training_fits`).

    Raises:
        ModelFitError: naming the layer or field and the fix.
    """
    model = getattr(model, 'module', model)
    num_steps = cfg.get('num_steps') or getattr(
        model.data_preprocessor, 'num_steps', None)
    name = getattr(cfg, 'filename', None) or 'the config'
    _check_classes(model, name)
    if num_steps is not None:
        _Probe(model, num_steps, name, _stem_hint(cfg, num_steps)).error(
            1, PROBE_SIDE, PROBE_SIDE, training=False)


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
    name = getattr(cfg, 'filename', None) or 'the config'
    _check_classes(model, name)
    crop = _crop(cfg, model)
    if num_steps is None or crop is None:
        return
    probe = _Probe(model, num_steps, name, _stem_hint(cfg, num_steps))
    side = probe.smallest_side(crop)
    if side is not None and min(crop) < side:
        raise ModelFitError(
            f'{name}: crop_size={crop} is below the smallest input the '
            f"model takes, {side}x{side} (its backbone's strides and "
            f'kernels); set --cfg-options crop_size={max(crop[0], side)},'
            f'{max(crop[1], side)} or larger')
    batch = cfg.get('train_dataloader', {}).get('batch_size')
    if batch == 1:
        failure = probe.error(1, *crop, training=True)
        if failure is not None and probe.error(
                2, *crop, training=True) is None:
            raise ModelFitError(
                f'{name}: train_dataloader.batch_size=1 does not train this '
                f'model: {cut(str(failure), 200)} (a batch norm after a '
                f'pooled 1x1 branch sees one value per channel); the smallest '
                f'batch_size that works is 2')
