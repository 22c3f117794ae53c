"""Everything about WGSE on a GPU, measured in one run: docs/gpu.md and
gpu.json beside it.

What ``dev/gpu_report.py`` runs (on a GPU machine that has
torch and triton but nothing of OpenMMLab: ``bash dev/gpu_report.sh``).
Every figure is measured in the same run as the baseline it is divided by.
Sections:

* ``correctness``: WGSE with the ``'triton'`` and ``'torch'`` backends on
  the device against the same weights in float64 (``'torch'`` backend), at
  full float32 (``'ieee'``: TF32 off), TF32, bf16 autocast and fp16
  autocast under AMP's loss scale (:data:`LOSS_SCALE`): the largest
  error of the output and of each parameter gradient relative to the
  largest magnitude of that tensor (or a hundredth of the largest of all);
  full float32 against
  :data:`~wgse_mmseg.core.wgse.triton_band_networks.TOLERANCES`, the
  others measured, not judged (:data:`REDUCED_PRECISION_NOTE`).
* ``wgse``: forward+backward of the reference design and of every backend
  that runs on the device (:mod:`.wgse`'s worker, a fresh process
  each): median time and peak memory, and both over the reference's.
* ``profile``: one WGSE pass under the profiler at TF32 and bf16, kernel
  by kernel, with the gaps between kernels and the band kernels' TFLOP/s
  against the device's peak (:mod:`.wgse_profile`; a GPU's only).
* ``segmentation`` and ``latency``: PSPNet and SegFormer-B0 training steps,
  raw spikes and WGSE
  (:func:`wgse_bench.segmentation.measure_train_step`:
  time, peak memory; WGSE's over raw), and inference at batch 1
  (``measure_latency``: WGSE's added milliseconds).
* ``paper``: the PSPNet step, raw and with WGSE, at the paper's shape
  (2 x 129 x 512 x 1024): time and peak memory.
* ``first_use``: the first-use check ``backend='auto'`` runs before it
  uses the Triton kernel on the device
  (:mod:`~wgse_mmseg.core.wgse.first_use_check`), at each precision: passed
  or what failed, the largest error, its seconds, and the backend ``'auto'``
  runs then; the ``wgse`` and ``correctness`` sections have the Triton
  kernel and the ``torch`` fallback side by side.
* ``targets``: the figures of :data:`FIGURES` against the targets the
  caller gives (``dev/gpu_report.py`` holds docs/gpu.md's).

A measurement that fails (out of memory, a missing package) is recorded
with its error and the report goes on; the segmentation sections import
the MMSeg layer in their own jobs, so without OpenMMLab they fail and the
WGSE sections still run. On CUDA every segmentation job runs in a fresh
process (:func:`~wgse_bench.machine.run_isolated`), so an
out-of-memory error or a broken CUDA context ends that job alone.
:data:`SMOKE` runs the same code on the CPU at tiny shapes (Triton in its
interpreter), which CI runs.
"""
import copy
import hashlib
import json
import os
import time
from contextlib import contextmanager, nullcontext
from typing import (Any, Callable, Dict, Iterator, List, NamedTuple,
                    Optional, Sequence, Tuple, Union)

import torch

from wgse_mmseg.fileio.atomic import atomic_output
from wgse_mmseg.core.wavelets import band_lengths
from wgse_mmseg.core.wgse import (WGSE, band_network_backends, first_use_check,
                                  triton_band_networks)

from . import wgse as wgse_benchmark
from . import wgse_choices, wgse_profile
from .machine import machine_record, run_isolated
from .markdown import markdown_table

__all__ = ['run_report']

Shape = Tuple[int, int, int, int]


class Plan(NamedTuple):
    """What one report measures: shapes ``(B, T, H, W)``, repeats."""
    device: str
    correctness_shape: Shape
    wgse_shape: Shape
    wgse_repeat: int
    train_shape: Shape
    paper_shape: Shape
    repeat: int  # timed training steps and batch-1 inferences
    warmup: int
    isolate: bool  # each segmentation job in a fresh process
    #: pixels of the first-use check's problem (None: the backend's own)
    check_pixels: Optional[int] = None


#: One H100 in 209 s with triton's cache warm, about 7 minutes with it
#: empty (docs/gpu.md). T = 129 everywhere, so the
#: band lengths (hence the compiled kernel variants) are shared.
GPU = Plan('cuda', correctness_shape=(2, 129, 16, 24),
           wgse_shape=(4, 129, 256, 512), wgse_repeat=10,
           train_shape=(4, 129, 256, 512), paper_shape=(2, 129, 512, 1024),
           repeat=10, warmup=3, isolate=True)
#: The same code paths on the CPU in seconds (CI): Triton's interpreter,
#: whose first-use check runs one pixel (a partial tile of each launch
#: entry; the check over several tiles: tests/core/wgse/
#: test_first_use_check.py).
SMOKE = Plan('cpu', correctness_shape=(1, 12, 3, 5),
             wgse_shape=(1, 12, 3, 4), wgse_repeat=1,
             train_shape=(2, 12, 32, 32), paper_shape=(2, 12, 32, 48),
             repeat=1, warmup=1, isolate=False, check_pixels=1)
#: Precisions of the correctness section (TF32 off, TF32, bf16 autocast,
#: fp16 autocast with the loss scaled as AMP scales it).
PRECISIONS = wgse_choices.PRECISIONS
#: The loss scale of the fp16 rows: ``torch.amp.GradScaler``'s initial
#: scale, the largest it uses before it first meets an overflow.
LOSS_SCALE = 2.0 ** 16
_AUTOCAST = {'bf16': torch.bfloat16, 'fp16': torch.float16}
#: model -> (raw-spike config, WGSE config), relative to the repository
MODELS = {
    'PSPNet R50-D8': ('configs/pspnet_raw.py', 'configs/pspnet_wgse.py'),
    'SegFormer-B0': ('configs/segformer_b0_raw.py',
                     'configs/segformer_b0_wgse.py'),
}
#: The figures a report can hold targets for: key -> (what, unit).
FIGURES = {
    'wgse_ms': ('WGSE forward+backward time', 'ms'),
    'wgse_bf16_ms': ('WGSE forward+backward under bf16 autocast (the '
                     'profiled pass)', 'ms'),
    'wgse_gib': ('WGSE forward+backward peak memory', 'GiB'),
    'step_ratio': ('PSPNet + WGSE step / raw step', 'x'),
    'step_ratio_amp': ('PSPNet + WGSE step / raw step, AMP (fp16)', 'x'),
    'segformer_step_ratio': ('SegFormer-B0 + WGSE step / raw step', 'x'),
    'added_latency_ms': ('PSPNet latency added by WGSE (batch 1)', 'ms'),
    'paper_gb': ("PSPNet + WGSE step at the paper's shape, peak memory",
                 'GB'),
    'paper_memory_ratio': ("PSPNet + WGSE / raw step's peak memory at the "
                           "paper's shape", 'x'),
    'first_use_s': ("the first-use check's longest wait (compiles and "
                    'checks)', 's'),
}
#: Targets: figure key -> (at most, a moonshot or None).
Targets = Dict[str, Tuple[float, Optional[float]]]


def _shape_text(shape: Sequence[int]) -> str:
    return 'x'.join(map(str, shape))


#: What a report measures the code of, relative to the repository: the
#: package, this measurement wing and the configs.
CODE = ('wgse_mmseg', 'wgse_bench', 'configs')


def code_digest(root: str) -> str:
    """16 hex digits of the SHA-256 of the measured code (every ``.py`` and
    ``.c`` file under :data:`CODE` in ``root``, path and contents): two
    reports with one digest measured the same code."""
    digest = hashlib.sha256()
    for top in CODE:
        for folder, dirs, files in sorted(os.walk(os.path.join(root, top))):
            dirs.sort()
            for name in sorted(files):
                if name.endswith(('.py', '.c')):
                    path = os.path.join(folder, name)
                    digest.update(os.path.relpath(path, root).encode())
                    with open(path, 'rb') as f:
                        digest.update(f.read())
    return digest.hexdigest()[:16]


def environment(device: str, root: str) -> Dict[str, Any]:
    """The device, driver and software versions of a report: the machine
    record (:func:`~wgse_bench.machine.machine_record`), whether Triton
    runs in its interpreter and the measured code's digest
    (:func:`code_digest` of the repository ``root``)."""
    return dict(machine_record(device),
                triton_interpreter=triton_band_networks.interpreting(),
                code=code_digest(root))


@contextmanager
def _precision(name: str, device_type: str) -> Iterator[None]:
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


def _output_and_grads(model: WGSE, spikes: torch.Tensor,
                      precision: Optional[str]) -> List[torch.Tensor]:
    """WGSE's output and the gradient of every parameter of
    ``sum(out * w)`` for a fixed ``w``, under ``precision`` if given: its
    TF32 setting for the forward and the backward pass (the ``'torch'``
    backend recomputes its forward in the backward), its autocast for the
    forward alone, as in training; at ``'fp16'`` the loss is multiplied by
    :data:`LOSS_SCALE` and the gradients divided by it, as AMP's
    ``GradScaler`` does."""
    model.zero_grad(set_to_none=True)
    with _precision(precision, spikes.device.type) \
            if precision else nullcontext():
        out = model(spikes)
        weights = torch.linspace(-1, 1, out.numel(), dtype=out.dtype,
                                 device=out.device).view_as(out)
        scale = LOSS_SCALE if precision == 'fp16' else 1.0
        with torch.autocast(spikes.device.type, enabled=False):
            ((out * weights).sum() * scale).backward()
    return [out.detach()] + [p.grad / scale for p in model.parameters()]


def _not_interpreted(precision: str) -> Optional[str]:
    """Why the Triton kernel is not run at ``precision`` in triton's CPU
    interpreter, or ``None`` (not interpreting, or ``'ieee'``)."""
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


#: Why the correctness section judges only full float32 against a tolerance
REDUCED_PRECISION_NOTE = (
    'measured, not judged: on random data, TF32, bf16 or fp16 rounding moves '
    'some pre-activations across zero, and the gradients behind them by up '
    'to about a fifth of their largest magnitude, in any implementation '
    "(compare the 'torch' row: cuDNN); the first-use check holds every "
    'precision to float32 accuracy on a problem where rounding is exact')


def check_correctness(shape: Shape, device: str) -> Dict[str, Any]:
    """The correctness section's rows (see the module docstring):
    ``{'rows': [{'backend', 'precision', 'max_rel_error', 'tensor',
    'tolerance', 'ok'}]}``. Full float32 (``'ieee'``) is judged against
    its tolerance; TF32 and bf16 are measured, ``ok`` ``None`` and ``note``
    saying why (:data:`REDUCED_PRECISION_NOTE`, or :func:`_not_interpreted`
    for Triton under the interpreter). A backend that raises gives a row
    with ``ok`` ``False`` and its ``error``; the other rows still run."""
    torch.manual_seed(0)
    model = WGSE().to(device)
    spikes = (torch.rand(shape, generator=torch.Generator().manual_seed(1))
              < 0.3).float().to(device)
    double = copy.deepcopy(model).double()
    double.backend = 'torch'
    want = _output_and_grads(double, spikes.double(), None)
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
            skipped = backend == 'triton' and _not_interpreted(precision)
            if skipped:
                rows.append(dict(row, ok=None, note=skipped))
                continue
            try:
                got = _output_and_grads(model, spikes, precision)
            except Exception as error:  # noqa: BLE001 - a finding
                rows.append(dict(row, ok=False, error=_error_message(error)))
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
    """The first-use section's rows: the check of the Triton backend for
    WGSE's default networks at ``T = steps`` on ``device``, at each of
    :data:`PRECISIONS` (``'bf16'`` and ``'tf32'`` noted, not run, under the
    interpreter: :func:`_not_interpreted`), as ``backend='auto'`` runs it
    before a training step (forward and backward, the coefficients needing
    no gradient): ``{'rows': [{'precision', 'passed', 'max_error', 'tolerance',
    'failure', 'seconds', 'auto_runs'}]}``.
    ``check_pixels`` shrinks the problem and runs the first launch entry
    alone (the smoke run's interpreter; the tests run every entry)."""
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
        skipped = _not_interpreted(precision)
        if skipped:
            rows.append(dict(precision=precision, passed=None, note=skipped))
            continue
        with _precision(precision, coeffs.device.type):
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
    ``latency``, its batch-1 inference), as
    :mod:`wgse_bench.segmentation` measures them; with ``amp`` under
    mmengine's ``AmpOptimWrapper`` (fp16 autocast, dynamic loss scale: what
    ``tools/train.py --amp`` runs). Sets the MMSeg layer up (explicitly, as
    the tools do) and imports it."""
    from wgse_mmseg import register_all_modules
    register_all_modules()
    from . import segmentation
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


def _error_message(error: Exception) -> str:
    """What a report records of an exception: its type and message, the
    last 2000 characters of a longer one."""
    message = f'{type(error).__name__}: {error}'.strip()
    return message if len(message) <= 2000 else '...' + message[-2000:]


def _error_line(row: Dict) -> str:
    """The last line of a row's recorded error, for a table cell."""
    return row['error'].splitlines()[-1][:120]


class _Clock:
    """Progress lines with the time since the report started."""

    def __init__(self):
        self.start = time.perf_counter()

    def attempt(self, label: str, fn: Callable, *args,
                isolate: bool = False, **kwargs) -> Dict[str, Any]:
        """``fn(*args, **kwargs)`` (a dict), with ``status`` ``'ok'`` and
        ``seconds``; ``status`` ``'failed'`` and ``error`` if it raised."""
        print(f'[gpu_report {self.elapsed():6.1f} s] {label} ...',
              flush=True)
        begin = time.perf_counter()
        try:
            result = run_isolated(fn, *args, **kwargs) if isolate else \
                fn(*args, **kwargs)
        except Exception as error:  # a failed measurement is a finding
            message = _error_message(error)
            print(f'    failed: {message.splitlines()[-1]}', flush=True)
            if torch.cuda.is_available():
                torch.cuda.empty_cache()
            return dict(status='failed', error=message,
                        seconds=time.perf_counter() - begin)
        return dict(result, status='ok', seconds=time.perf_counter() - begin)

    def elapsed(self) -> float:
        return time.perf_counter() - self.start


def _status(rows: Sequence[Dict]) -> str:
    statuses = {r['status'] for r in rows}
    return statuses.pop() if len(statuses) == 1 else 'partial'


def _ratio(value: Optional[float], base: Optional[float]) -> Optional[float]:
    return None if value is None or not base else value / base


def _wgse_section(plan: Plan, clock: _Clock) -> Dict[str, Any]:
    text = _shape_text(plan.wgse_shape)
    rows = []
    for impl in ['reference'] + wgse_benchmark.available_backends(plan.device):
        row = clock.attempt(
            f'WGSE forward+backward, {impl}, {text}',
            wgse_benchmark.run_worker,
            [impl, text, str(plan.wgse_repeat), '--device', plan.device])
        rows.append(dict(row, impl=impl))
    base = rows[0] if rows[0]['status'] == 'ok' else {}
    for row in rows:
        if row['status'] == 'ok':
            row['time_vs_reference'] = _ratio(row['median_s'],
                                              base.get('median_s'))
            row['memory_vs_reference'] = _ratio(row['peak_mib'],
                                                base.get('peak_mib'))
    return dict(status=_status(rows), shape=list(plan.wgse_shape),
                rows=rows)


def _profile_section(plan: Plan, clock: _Clock) -> Dict[str, Any]:
    """One WGSE pass at the ``wgse`` section's shape under the profiler, at
    TF32 and bf16 (:mod:`.wgse_profile`); a GPU's only."""
    if not plan.device.startswith('cuda'):
        return dict(status='ok', rows=[],
                    note=f'not run: profiling needs a GPU ({plan.device})')
    rows = [dict(clock.attempt(
        f'profile of one WGSE pass, {precision}, '
        f'{_shape_text(plan.wgse_shape)}', wgse_profile.profile_pass,
        plan.wgse_shape, plan.device, precision), precision=precision)
        for precision in ('tf32', 'bf16')]
    return dict(status=_status(rows), shape=list(plan.wgse_shape),
                rows=rows)


def _model_rows(plan: Plan, clock: _Clock, shape: Shape, latency: bool,
                models: Dict[str, Tuple[str, str]], root: str,
                amp: bool = False) -> List[Dict[str, Any]]:
    rows = []
    for model, configs in models.items():
        for enhancer, config in zip(('raw', 'WGSE'), configs):
            enhancer += ', AMP' if amp else ''
            row = clock.attempt(
                f'{model} {enhancer} step, {_shape_text(shape)}',
                segmentation_step, os.path.join(root, config), shape,
                plan.repeat, plan.warmup, plan.device, latency, amp,
                isolate=plan.isolate)
            rows.append(dict(row, model=model, enhancer=enhancer,
                             config=config))
        raw, wgse = rows[-2:]
        if raw['status'] == wgse['status'] == 'ok':
            wgse['step_vs_raw'] = (wgse['step_ms']['median'] /
                                   raw['step_ms']['median'])
            wgse['memory_vs_raw'] = (wgse['memory']['peak_mb'] /
                                     raw['memory']['peak_mb'])
            if latency:
                wgse['added_latency_ms'] = (wgse['latency_ms']['median'] -
                                            raw['latency_ms']['median'])
    return rows


def _pspnet(models: Dict[str, Tuple[str, str]]
            ) -> Dict[str, Tuple[str, str]]:
    """PSPNet of ``models`` (the paper's shape and AMP run it alone), or
    the first model."""
    return {name: configs for name, configs in models.items()
            if name == 'PSPNet R50-D8'} or dict(list(models.items())[:1])


def _figures(sections: Dict[str, Dict]) -> Dict[str, Optional[float]]:
    """Each of :data:`FIGURES` in this report, ``None`` where it was not
    measured."""
    def rows(name: str) -> List[Dict[str, Any]]:  # none: not measured
        return sections.get(name, {}).get('rows', [])

    wgse = {r['impl']: r for r in rows('wgse') if r['status'] == 'ok'}
    # what 'auto' runs on the device: Triton on CUDA, else the fastest
    row = wgse.get('triton') or wgse.get('compiled') or wgse.get('torch')

    def step(model: str, enhancer: str) -> Dict[str, Any]:
        return next((r for r in rows('segmentation')
                     if r['model'] == model and r['enhancer'] == enhancer),
                    {})

    pspnet = step('PSPNet R50-D8', 'WGSE')
    paper = [r for r in rows('paper') if r['status'] == 'ok']
    paper_wgse = [r for r in paper if r['enhancer'] == 'WGSE']
    bf16 = [r for r in rows('profile')
            if r['status'] == 'ok' and r['precision'] == 'bf16']
    waits = [r['seconds'] for r in rows('first_use')
             if r.get('seconds') is not None]
    return dict(
        wgse_ms=None if row is None else 1e3 * row['median_s'],
        wgse_bf16_ms=bf16[0]['span_ms'] if bf16 else None,
        wgse_gib=None if row is None else row['peak_mib'] / 1024,
        step_ratio=pspnet.get('step_vs_raw'),
        step_ratio_amp=step('PSPNet R50-D8', 'WGSE, AMP').get('step_vs_raw'),
        segformer_step_ratio=step('SegFormer-B0', 'WGSE').get('step_vs_raw'),
        added_latency_ms=pspnet.get('added_latency_ms'),
        paper_gb=(paper_wgse[0]['memory']['peak_mb'] * 2**20 / 1e9
                  if paper_wgse else None),
        paper_memory_ratio=paper_wgse[0].get('memory_vs_raw')
        if paper_wgse else None,
        first_use_s=max(waits) if waits else None)


def _targets(sections: Dict[str, Dict],
             targets: Targets) -> List[Dict[str, Any]]:
    """Each of ``targets`` with the figure of this report (``None`` where
    it was not measured) and whether it is met."""
    figures = _figures(sections)
    found = []
    for key, (limit, moonshot) in targets.items():
        what, unit = FIGURES[key]
        value = figures[key]
        met = None if value is None else value <= limit
        found.append(dict(what=what, unit=unit, target=limit,
                          moonshot=moonshot, value=value, met=met,
                          moonshot_met=None if value is None or
                          moonshot is None else value <= moonshot))
    return found


#: The report's sections in the order they run ('latency' comes with the
#: segmentation steps, 'targets' from the others).
SECTIONS = ('correctness', 'first_use', 'wgse', 'profile', 'segmentation',
            'latency', 'paper', 'targets')
#: What a section holds until it is measured: a run stopped by a time limit
#: leaves the sections it finished and these.
NOT_RUN = dict(status='not run',
               note='not measured: the run stopped before this section')
#: Environment entries that may differ between runs whose sections one
#: report keeps together (:func:`kept_sections`)
_VOLATILE = ('load_average', )


def _correctness_section(plan: Plan, clock: _Clock) -> Dict[str, Any]:
    section = clock.attempt(
        f'correctness against float64, {_shape_text(plan.correctness_shape)}',
        check_correctness, plan.correctness_shape, plan.device)
    if section['status'] == 'ok' and any(
            r['ok'] is False for r in section['rows']):
        section['status'] = 'failed'
        section['error'] = 'raised or outside the tolerance: ' + \
            ', '.join(f"{r['backend']} {r['precision']}"
                      for r in section['rows'] if r['ok'] is False)
    return dict(section, shape=list(plan.correctness_shape))


def _first_use_section(plan: Plan, clock: _Clock) -> Dict[str, Any]:
    section = clock.attempt(
        f'first-use check of the Triton kernel, T={plan.wgse_shape[1]}',
        check_first_use, plan.wgse_shape[1], plan.device, plan.check_pixels)
    if section['status'] == 'ok' and any(
            r['passed'] is False for r in section['rows']):
        section['status'] = 'failed'
        section['error'] = 'failed: ' + ', '.join(
            r['precision'] for r in section['rows'] if r['passed'] is False)
    return section


def _segmentation_sections(plan: Plan, clock: _Clock,
                           models: Dict[str, Tuple[str, str]], root: str
                           ) -> Dict[str, Dict[str, Any]]:
    """The ``segmentation`` section and the ``latency`` section its steps
    give."""
    rows = _model_rows(plan, clock, plan.train_shape, True, models, root)
    if plan.device.startswith('cuda'):  # AMP: fp16 autocast, CUDA only
        rows += _model_rows(plan, clock, plan.train_shape, False,
                            _pspnet(models), root, amp=True)
    latency = dict(
        status=_status(rows),
        shape=[1] + list(plan.train_shape[1:]), rows=[
            {k: r.get(k) for k in ('model', 'enhancer', 'status',
                                   'latency_ms', 'added_latency_ms')}
            for r in rows if 'AMP' not in r['enhancer']])
    return dict(segmentation=dict(status=_status(rows),
                                  shape=list(plan.train_shape), rows=rows),
                latency=latency)


def _paper_section(plan: Plan, clock: _Clock,
                   models: Dict[str, Tuple[str, str]], root: str
                   ) -> Dict[str, Any]:
    rows = _model_rows(plan, clock, plan.paper_shape, False,
                       _pspnet(models), root)
    return dict(status=_status(rows), shape=list(plan.paper_shape),
                rows=rows)


def kept_sections(earlier: Optional[Dict[str, Any]], plan: Plan,
                  env: Dict[str, Any]) -> Tuple[List[str], str]:
    """The sections of ``earlier`` (a report's JSON) that a report of
    ``plan`` in ``env`` keeps instead of measuring them again: those that
    finished ``'ok'``, where ``earlier`` ran the same plan with the same
    code on the same machine and software (the environment but its load).
    Returns them and a line saying what is kept, or why nothing is."""
    if earlier is None:
        return [], 'no earlier report: every section is measured'

    def steady(record):
        return {k: v for k, v in record.items() if k not in _VOLATILE} \
            if isinstance(record, dict) else record

    differs = [what for what, same in (
        ('plan', earlier.get('plan') == json.loads(json.dumps(
            plan._asdict()))),
        ('environment', steady(earlier.get('environment')) == steady(env)))
        if not same]
    if differs:
        return [], (f"the earlier report's {' and '.join(differs)} differ "
                    'from this run: every section is measured')
    found = earlier.get('sections')
    kept = [name for name in SECTIONS[:-1] if isinstance(found, dict) and
            isinstance(found.get(name), dict) and
            found[name].get('status') == 'ok']
    return kept, ('kept from the earlier report: ' + (', '.join(kept) or
                                                      'none'))


def run_report(plan: Plan, root: str, targets: Targets,
               models: Optional[Dict[str, Tuple[str, str]]] = None,
               earlier: Optional[Dict[str, Any]] = None,
               save: Optional[Callable[[Dict[str, Any]], None]] = None
               ) -> Dict[str, Any]:
    """Measure every section of the module docstring; ``root`` is the
    repository (where the configs of ``models``, default PSPNet and
    SegFormer-B0, are), ``targets`` what the figures are judged against.
    ``earlier``: a report whose finished sections are kept where it ran the
    same plan and code on the same machine and software (a run resumed
    after a time limit stopped it). ``save`` is called with the report so far
    after each section, so that a run stopped part-way leaves what it measured.
    Returns the JSON-ready report (``kept``: the sections taken from
    ``earlier``)."""
    models = MODELS if models is None else models
    clock = _Clock()
    print(f'[gpu_report] {plan.device}: {plan._asdict()}', flush=True)
    env = environment(plan.device, root)
    print(' | '.join(f'{k}: {v}' for k, v in env.items()), flush=True)
    steps = [
        (('correctness', ), lambda: dict(
            correctness=_correctness_section(plan, clock))),
        (('first_use', ), lambda: dict(
            first_use=_first_use_section(plan, clock))),
        (('wgse', ), lambda: dict(wgse=_wgse_section(plan, clock))),
        (('profile', ), lambda: dict(profile=_profile_section(plan, clock))),
        (('segmentation', 'latency'), lambda: _segmentation_sections(
            plan, clock, models, root)),
        (('paper', ), lambda: dict(paper=_paper_section(plan, clock, models,
                                                        root))),
    ]
    finished, why = kept_sections(earlier, plan, env)
    print(f'[gpu_report] {why}', flush=True)
    # a step's sections are kept together or measured together
    kept = [name for names, _ in steps
            if all(name in finished for name in names) for name in names]
    sections = {name: dict(NOT_RUN) for name in SECTIONS}
    sections.update({name: earlier['sections'][name] for name in kept})
    report = dict(plan=plan._asdict(), environment=env, sections=sections,
                  kept=kept, seconds=0.0)
    for names, measure in steps:
        if names[0] not in kept:
            sections.update(measure())
        sections['targets'] = dict(status='ok',
                                   rows=_targets(sections, targets))
        report['seconds'] = clock.elapsed()
        if save is not None:
            save(report)
    print(f'[gpu_report {clock.elapsed():6.1f} s] done', flush=True)
    return report


def _num(value: Optional[float], digits: Union[int, str] = 2) -> str:
    """``value`` with ``digits`` decimals (or that format), ``'-'`` for
    ``None``."""
    spec = f'.{digits}f' if isinstance(digits, int) else digits
    return '-' if value is None else format(value, spec)


def _timing(summary: Optional[Dict], digits: int = 1) -> str:
    return '-' if summary is None else \
        f"{summary['median']:.{digits}f} ± {summary['mad']:.{digits}f}"


def _failed(section: Dict) -> str:
    return (f"**Failed**: `{section['error'].splitlines()[-1]}` "
            '(the whole message is in the JSON).\n')


def _row_status(row: Dict) -> str:
    return 'ok' if row['status'] == 'ok' else \
        'failed: ' + _error_line(row)


def _within(row: Dict) -> str:
    """The correctness table's last column for ``row``."""
    if row.get('error'):
        return 'NO: ' + _error_line(row)
    if row['ok'] is None:
        return 'measured' if row.get('note') == REDUCED_PRECISION_NOTE \
            else row['note']
    return 'yes' if row['ok'] else 'NO'


def _model_table(rows: Sequence[Dict], latency: bool) -> str:
    headers = ['model', 'input', 'enh. backend', 'step ms', 'step / raw',
               'peak MiB', 'memory / raw']
    if latency:
        headers += ['latency ms (b1)', 'added ms']
    headers.append('status')
    table = []
    for r in rows:
        ok = r['status'] == 'ok'
        line = [r['model'], r['enhancer'],
                (r.get('enhancer_backend') or '-') if ok else '-',
                _timing(r.get('step_ms')), _num(r.get('step_vs_raw')),
                _num(r['memory']['peak_mb'], 0) if ok else '-',
                _num(r.get('memory_vs_raw'))]
        if latency:
            line += [_timing(r.get('latency_ms'), 2),
                     _num(r.get('added_latency_ms'))]
        table.append(line + [_row_status(r)])
    return markdown_table(headers, table)


def _correctness_lines(section: Dict[str, Any]) -> List[str]:
    out = [f"WGSE at {_shape_text(section['shape'])}, the same weights "
           'in float64 (backend `torch`) as reference; error: largest over '
           'the output and every parameter gradient of |got - float64| / '
           'the largest magnitude of that tensor (a hundredth of the '
           'largest of all at least). Full float32 is held to its '
           'tolerance; TF32 and bf16 are ' + REDUCED_PRECISION_NOTE + '.',
           '']
    if 'rows' in section:
        out += [markdown_table(
            ['backend', 'precision', 'max rel. error', 'in', 'tolerance',
             'within'],
            [[r['backend'], r['precision'],
              _num(r['max_rel_error'], '.1e'), r['tensor'] or '-',
              _num(r['tolerance'], '.0e'), _within(r)]
             for r in section['rows']]), '']
    return out


def _first_use_lines(section: Dict[str, Any]) -> List[str]:
    out = ["What `backend='auto'` checks before it first runs the Triton "
           'kernel on the device for a training step: the launch entries it '
           'runs, forward and backward, against the `torch` backend in '
           'float64 (`wgse_mmseg/core/wgse/first_use_check.py`); where it '
           "fails, 'auto' runs `torch`.", '']
    if section.get('rows'):
        out += [markdown_table(
            ['precision', 'passed', 'max rel. error', 'tolerance', 'failure',
             'seconds', "'auto' runs"],
            [[r['precision'],
              {True: 'yes', False: 'NO'}.get(r['passed'], r.get('note')),
              _num(r.get('max_error'), '.1e'),
              _num(r.get('tolerance'), '.0e'),
              r.get('failure') or '-',
              _num(r.get('seconds')), r.get('auto_runs', '-')]
             for r in section['rows']]), '']
    elif section.get('note'):
        out += [section['note'], '']
    return out


def _wgse_lines(section: Dict[str, Any]) -> List[str]:
    return [f"db8, 5 levels, 32 channels, {_shape_text(section['shape'])}, "
            'the output gradient given (a fixed random tensor made before '
            'the pass, as a segmentor hands WGSE one), TF32 as torch '
            'defaults; peak: growth of memory allocated (CUDA) or of peak '
            'RSS (CPU) in one pass.', '',
            markdown_table(
                ['implementation', 'median ms', 'min-max ms', 'peak MiB',
                 'time / reference', 'memory / reference', 'status'],
                [[wgse_choices.IMPLEMENTATIONS[r['impl']],
                  _num(1e3 * r['median_s'], 1) if 'median_s' in r else '-',
                  f"{1e3 * r['min_s']:.1f}-{1e3 * r['max_s']:.1f}"
                  if 'min_s' in r else '-',
                  _num(r.get('peak_mib'), 0),
                  _num(r.get('time_vs_reference'), 3),
                  _num(r.get('memory_vs_reference'), 3), _row_status(r)]
                 for r in section['rows']]), '']


def _profile_lines(section: Dict[str, Any]) -> List[str]:
    out = ['Device kernels of one forward+backward at the shape above '
           '(torch.profiler, after a warm-up pass): time, share of the span '
           'from the first kernel to the last, the gaps no kernel covers, '
           "and the band kernels' H x H products in TFLOP/s against the "
           "device's dense peak (wgse_bench/wgse_profile.py).", '']
    if section.get('note'):
        out += [section['note'], '']
    for row in section.get('rows', []):
        if row['status'] == 'ok':
            out += [f"{row['precision']} ({row['backend']}): span "
                    f"{row['span_ms']:.2f} ms", '',
                    *wgse_profile.table_lines(row), '']
        else:
            out += [f"{row['precision']}: {_row_status(row)}", '']
    return out


def _segmentation_lines(section: Dict[str, Any]) -> List[str]:
    return [f"Batch {section['shape'][0]}, T={section['shape'][1]}, "
            f"{section['shape'][2]}x{section['shape'][3]}, "
            "`model.train_step` with the config's optimiser; time: median "
            '± MAD; peak: CUDA memory allocated (CPU: peak RSS) during the '
            'timed steps; ratios: WGSE over raw spikes.', '',
            _model_table(section['rows'], latency=False), '']


def _latency_lines(section: Dict[str, Any]) -> List[str]:
    return ['`model.test_step` on one stream (preprocessing, enhancer, '
            'segmentor, resize, argmax), no gradients; WGSE\'s added '
            'milliseconds over raw spikes.', '',
            markdown_table(
                ['model', 'input', 'latency ms', 'added ms', 'status'],
                [[r['model'], r['enhancer'], _timing(r['latency_ms'], 2),
                  _num(r['added_latency_ms']),
                  'ok' if r['status'] == 'ok' else 'failed']
                 for r in section['rows']]), '']


def _paper_lines(section: Dict[str, Any]) -> List[str]:
    return [f"{_shape_text(section['shape'])} (batch x T x H x W), training "
            'step as above.', '', _model_table(section['rows'], False), '']


def _targets_lines(section: Dict[str, Any]) -> List[str]:
    return [markdown_table(
        ['target', 'this run', 'at most', 'aim', 'met'],
        [[t['what'], '-' if t['value'] is None else
          f"{t['value']:.2f} {t['unit']}",
          f"{t['target']} {t['unit']}",
          '-' if t['moonshot'] is None else f"{t['moonshot']} {t['unit']}",
          'not measured' if t['met'] is None else
          ('yes' if t['met'] else 'no') +
          (' (aim too)' if t['moonshot_met'] else '')]
         for t in section['rows']]), '']


#: Each section's heading in docs/gpu.md and what goes under it.
_SECTION_TEXT = dict(
    correctness=('Correctness against float64', _correctness_lines),
    first_use=('First-use check', _first_use_lines),
    wgse=('WGSE forward+backward', _wgse_lines),
    profile=('One WGSE pass, kernel by kernel', _profile_lines),
    segmentation=('Training steps', _segmentation_lines),
    latency=('Latency at batch 1', _latency_lines),
    paper=("The paper's shape", _paper_lines),
    targets=('Against the targets (issue 43: an H100 or H200)',
             _targets_lines))


def format_report(report: Dict[str, Any], command: str) -> str:
    """docs/gpu.md: every section as a table (a section not measured says
    so), the environment and the command that produced it."""
    env, sections = report['environment'], report['sections']
    device = env.get('gpu', f"{env['device']} ({env['cpu']})")
    out = [f'# WGSE on {device}', '',
           'Written by `' + command + '` (docs/wgse_speed.md, "On a GPU"); '
           'every ratio is against a baseline measured in the same run. '
           'The JSON beside this file has every number and raw sample.', '',
           markdown_table(['', ''], [[k, v] for k, v in env.items()]), '']
    if not env['device'].startswith('cuda'):
        out += ['**Not a GPU run**: the smoke run on the CPU at tiny shapes '
                '(Triton in its interpreter); its figures say nothing about '
                'a GPU.', '']
    if report.get('kept'):
        out += ['Kept from an earlier run of the same plan and code on the '
                'same machine and software (`--resume`): ' +
                ', '.join(report['kept']) + '.', '']
    for name in SECTIONS:
        section = sections[name]
        heading, lines = _SECTION_TEXT[name]
        out += [f'## {heading}', '']
        if section['status'] == 'not run':
            out += [f"**Not run**: {section['note']}.", '']
            continue
        out += lines(section)
        if name in ('correctness', 'first_use') and \
                section['status'] != 'ok':
            out.append(_failed(section))
    out += [f"The report took {report['seconds']:.0f} s.", '']
    return '\n'.join(out)


def read_report(path: str) -> Dict[str, Any]:
    """The report whose JSON :func:`write_report` wrote at ``path``.

    Raises:
        ValueError: naming ``path``, where it cannot be read as JSON or
            holds no JSON object.
    """
    try:
        with open(path, 'rb') as f:
            report = json.loads(f.read())
    except (OSError, ValueError) as err:
        raise ValueError(f'{path} cannot be read as a report ({err})')
    if not isinstance(report, dict):
        raise ValueError(f'{path} holds no report (a JSON object), but '
                         f'{type(report).__name__}')
    return report


def write_report(report: Dict[str, Any], out_dir: str, command: str) -> None:
    """``out_dir/gpu.json`` and ``out_dir/gpu.md``, each whole or not at
    all."""
    with atomic_output(os.path.join(out_dir, 'gpu.json')) as f:
        f.write(json.dumps(report, indent=1).encode())
    with atomic_output(os.path.join(out_dir, 'gpu.md')) as f:
        f.write(format_report(report, command).encode())
