"""The report's checks and model measurements, each a function of shapes
and a device that returns a JSON-ready dict: correctness against float64,
the first-use check ``backend='auto'`` runs, and a segmentor's training
step and batch-1 latency."""
import copy
from contextlib import contextmanager, nullcontext
from typing import Any, Dict, Iterator, List, Optional, Sequence, Tuple

import torch

from wgse_mmseg.core.wavelets import band_lengths
from wgse_mmseg.core.wgse import (WGSE, band_network_backends, first_use_check,
                                  triton_band_networks)

from .. import wgse as wgse_benchmark
from .. import wgse_choices

__all__ = []

Shape = Tuple[int, int, int, int]

#: Precisions of the correctness section (TF32 off, TF32, bf16 autocast,
#: fp16 autocast with the loss scaled as AMP scales it).
PRECISIONS = wgse_choices.PRECISIONS
#: The loss scale of the fp16 rows: ``torch.amp.GradScaler``'s initial
#: scale, the largest it uses before it first meets an overflow.
LOSS_SCALE = 2.0 ** 16
_AUTOCAST = {'bf16': torch.bfloat16, 'fp16': torch.float16}
#: Why the correctness section judges only full float32 against a tolerance
REDUCED_PRECISION_NOTE = (
    'measured, not judged: on random data, TF32, bf16 or fp16 rounding moves '
    'some pre-activations across zero, and the gradients behind them by up '
    'to about a fifth of their largest magnitude, in any implementation '
    "(compare the 'torch' row: cuDNN); the first-use check holds every "
    'precision to float32 accuracy on a problem where rounding is exact')


def error_message(error: BaseException) -> str:
    """What a report records of an exception: its type and message, the
    last 2000 characters of a longer one."""
    message = f'{type(error).__name__}: {error}'.strip()
    return message if len(message) <= 2000 else '...' + message[-2000:]


def ratio(value: Optional[float], base: Optional[float]) -> Optional[float]:
    """``value / base``, ``None`` where either is missing (or ``base`` 0)."""
    return None if value is None or not base else value / base


@contextmanager
def precision_of(name: str, device_type: str) -> Iterator[None]:
    """TF32 off (``'ieee'``) or on (``'tf32'``, for cuDNN and matmul), or
    bf16 or fp16 autocast (``'bf16'``, ``'fp16'``; TF32 off) within the
    block."""
    saved = (torch.backends.cudnn.allow_tf32,
             torch.backends.cuda.matmul.allow_tf32)
    torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 \
        = name == 'tf32'
    try:
        with torch.autocast(device_type,
                            dtype=_AUTOCAST.get(name, torch.bfloat16),
                            enabled=name in _AUTOCAST):
            yield
    finally:
        (torch.backends.cudnn.allow_tf32,
         torch.backends.cuda.matmul.allow_tf32) = saved


def output_and_grads(model: torch.nn.Module, spikes: torch.Tensor,
                     precision: Optional[str]) -> List[torch.Tensor]:
    """WGSE's output and the gradient of every parameter of
    ``sum(out * w)`` for a fixed ``w``, under ``precision`` if given: its
    TF32 setting for the forward and the backward pass (the ``'torch'``
    backend recomputes its forward in the backward), its autocast for the
    forward alone, as in training; at ``'fp16'`` the loss is multiplied by
    :data:`LOSS_SCALE` and the gradients divided by it, as AMP's
    ``GradScaler`` does."""
    model.zero_grad(set_to_none=True)
    with precision_of(precision, spikes.device.type) \
            if precision else nullcontext():
        out = model(spikes)
        weights = torch.linspace(-1, 1, out.numel(), dtype=out.dtype,
                                 device=out.device).view_as(out)
        scale = LOSS_SCALE if precision == 'fp16' else 1.0
        with torch.autocast(spikes.device.type, enabled=False):
            ((out * weights).sum() * scale).backward()
    return [out.detach()] + [p.grad / scale for p in model.parameters()]


def not_interpreted(precision: str) -> Optional[str]:
    """Why the Triton kernel's results are not judged at ``precision`` in
    triton's CPU interpreter, or ``None`` (not interpreting, or
    ``'ieee'``)."""
    if not triton_band_networks.interpreting():
        return None
    if precision == 'bf16':
        return ("not run: triton 3.6's interpreter multiplies bf16 tl.dot "
                'operands as raw 16-bit integers')
    if precision == 'fp16':
        return ('not run: its gradient products take bf16 operands, which '
                "triton 3.6's interpreter multiplies as raw 16-bit integers")
    if precision == 'tf32':
        return ("not run: triton's interpreter ignores tl.dot's "
                "input_precision, so its tf32 is the 'ieee' row's arithmetic")
    return None


def check_correctness(shape: Shape, device: str) -> Dict[str, Any]:
    """WGSE with the ``'triton'`` and ``'torch'`` backends on ``device``
    against the same weights in float64 on a ``(B, T, H, W)`` batch, at each
    of :data:`PRECISIONS`: ``{'rows': [{'backend', 'precision',
    'max_rel_error', 'tensor', 'tolerance', 'ok'}]}``, the error the largest
    over the output and every parameter gradient, relative to that tensor's
    largest magnitude. Full float32 (``'ieee'``) is judged against its
    tolerance; the others are measured, ``ok`` ``None`` and ``note`` saying
    why (:data:`REDUCED_PRECISION_NOTE`, or :func:`not_interpreted`). A
    backend that raises gives a row with ``ok`` ``False`` and its
    ``error``; the other rows still run."""
    torch.manual_seed(0)
    model = WGSE().to(device)
    spikes = spikes_like(shape, device)
    double = copy.deepcopy(model).double()
    double.backend = 'torch'
    want = output_and_grads(double, spikes.double(), None)
    names = ['output'] + [name for name, _ in model.named_parameters()]
    backends = [b for b in ('triton', 'torch')
                if b in wgse_benchmark.available_backends(device)]
    rows = []
    for backend in backends:
        model.backend = backend
        for precision in PRECISIONS:
            row = dict(backend=backend, precision=precision,
                       max_rel_error=None, tensor=None,
                       tolerance=triton_band_networks.TOLERANCES['ieee']
                       if precision == 'ieee' else None)
            skipped = backend == 'triton' and not_interpreted(precision)
            if skipped:
                rows.append(dict(row, ok=None, note=skipped))
                continue
            try:
                got = output_and_grads(model, spikes, precision)
            except Exception as error:  # noqa: BLE001 - a finding
                rows.append(dict(row, ok=False, error=error_message(error)))
                continue
            errors = first_use_check.relative_errors(got, want)
            worst = max(range(len(errors)), key=errors.__getitem__)
            row.update(backend=model.backend_in_use,
                       max_rel_error=errors[worst], tensor=names[worst])
            if precision == 'ieee':
                row['ok'] = errors[worst] <= row['tolerance']
            elif errors[worst] == float('inf'):  # NaN or Inf
                row['ok'] = False
            else:
                row.update(ok=None, note=REDUCED_PRECISION_NOTE)
            rows.append(row)
    return dict(rows=rows)


def check_first_use(steps: int, device: str,
                    check_pixels: Optional[int] = None) -> Dict[str, Any]:
    """The check of the Triton backend for WGSE's default networks at
    ``T = steps`` on ``device``, at each of :data:`PRECISIONS` (noted, not
    run, where :func:`not_interpreted` says so), as ``backend='auto'`` runs
    it before a training step (forward and backward, the coefficients
    needing no gradient): ``{'rows': [{'precision', 'passed', 'max_error',
    'tolerance', 'failure', 'seconds', 'auto_runs'}]}``. ``check_pixels``
    shrinks the problem and runs the first launch entry alone (a dry run in
    the interpreter; the tests run every entry)."""
    backend = copy.copy(band_network_backends.BACKENDS['triton'])
    reason = backend.cannot_run(WGSE().band_networks)
    if reason:
        return dict(rows=[], note=f'not run: {reason}')
    if check_pixels is not None:
        backend.check_pixels = check_pixels
        launches = backend.check_launches
        backend.check_launches = lambda *call: launches(*call)[:1]
    model = WGSE().to(device)
    lengths = band_lengths(steps, model.wavelet, model.level, model.mode)
    coeffs = torch.zeros(1, 1, sum(lengths), device=device)
    rows = []
    for precision in PRECISIONS:
        skipped = not_interpreted(precision)
        if skipped:
            rows.append(dict(precision=precision, passed=None, note=skipped))
            continue
        with precision_of(precision, coeffs.device.type):
            check = first_use_check.check_on_first_use(
                backend, band_network_backends.BACKENDS['torch'],
                model.band_networks, coeffs, lengths)
        rows.append(dict(check._asdict(), precision=precision,
                         auto_runs='triton' if check.passed else 'torch'))
    return dict(rows=rows)


def segmentation_step(config: str, shape: Shape, repeat: int, warmup: int,
                      device: str, latency: bool = True,
                      amp: bool = False) -> Dict[str, Any]:
    """A config's training step on a ``(B, T, H, W)`` batch (and, if
    ``latency``, its batch-1 inference), as the segmentation benchmark
    measures them; with ``amp`` under mmengine's ``AmpOptimWrapper`` (fp16
    autocast, dynamic loss scale: what ``tools/train.py --amp`` runs). Sets
    the MMSeg layer up (explicitly, as the tools do) and imports it."""
    from wgse_mmseg import register_all_modules
    register_all_modules()
    from .. import segmentation
    batch, steps, height, width = shape
    cfg, model = segmentation.build_model(
        config, dict(num_steps=steps, crop_size=f'{height},{width}'),
        device=device)
    result = {}
    if latency:
        result['latency_ms'] = segmentation.measure_latency(
            model, steps, (height, width), repeat, warmup)
    optim_wrapper = dict(cfg.optim_wrapper)
    if amp:
        optim_wrapper.update(type='AmpOptimWrapper', loss_scale='dynamic')
    train = segmentation.measure_train_step(model, optim_wrapper, steps,
                                            (height, width), batch, repeat,
                                            warmup)
    enhancer = getattr(model.data_preprocessor, 'enhancer', None)
    return dict(result, step_ms=train['step_ms'], memory=train['memory'],
                enhancer_backend=getattr(enhancer, 'backend_in_use', None))


def spikes_like(shape: Sequence[int], device: str, seed: int = 1
                ) -> torch.Tensor:
    """A ``(B, T, H, W)`` float32 batch of random spikes (30% ones) on
    ``device``, the same for one ``seed``."""
    return (torch.rand(tuple(shape), generator=torch.Generator().manual_seed(
        seed)) < 0.3).float().to(device)
