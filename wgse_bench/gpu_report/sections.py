"""What a report measures and in which order: the plans (shapes, repeats),
the sections by value, each run and recorded (a failure is a finding), a
time budget that leaves the sections it has no room for to a resumed run,
and what a resumed run keeps of an earlier one."""
import hashlib
import json
import os
import time
from typing import (Any, Callable, Dict, List, NamedTuple, Optional,
                    Sequence, Tuple)

import torch

from wgse_mmseg.core.wgse import triton_band_networks

from .. import wgse as wgse_benchmark
from .. import wgse_profile
from ..machine import machine_record, run_isolated
from . import ceilings, kernels, measure
from .measure import Shape, error_message, ratio
from .targets import Targets, judge

__all__ = []


class Plan(NamedTuple):
    """What one report measures: shapes ``(B, T, H, W)``, repeats, sizes."""
    device: str
    kernel_shape: Shape  # the band kernels and the WGSE pass
    kernel_repeat: int
    stall_shape: Shape  # the profiled launches
    correctness_shape: Shape
    train_shape: Shape
    paper_shape: Shape
    repeat: int  # timed training steps and batch-1 inferences
    warmup: int
    isolate: bool  # each segmentation job in a fresh process
    copy_bytes: int  # the copy of the ceilings
    matmul_size: int  # the bf16 product of the ceilings
    dot_iterations: int  # products a program of the tensor-core loops
    dot_programs_per_sm: int
    precisions: Tuple[str, ...]  # the band kernels' and the pass's
    #: pixels of the first-use check's problem (None: the backend's own)
    check_pixels: Optional[int] = None


#: One H100 or H200. T = 129 everywhere, so the band lengths (hence the
#: compiled kernel variants) are shared.
GPU = Plan('cuda', kernel_shape=(4, 129, 256, 512), kernel_repeat=20,
           stall_shape=(1, 129, 256, 512), correctness_shape=(2, 129, 16, 24),
           train_shape=(4, 129, 256, 512), paper_shape=(2, 129, 512, 1024),
           repeat=10, warmup=3, isolate=True, copy_bytes=2 << 30,
           matmul_size=8192, dot_iterations=4096, dot_programs_per_sm=8,
           precisions=('tf32', 'bf16'))
#: Every section's code on the CPU in seconds at tiny shapes (Triton in its
#: interpreter): what the tests run before a GPU session. Its first-use
#: check runs one pixel (a partial tile of each launch entry); its kernels
#: are timed at TF32 alone (bf16 runs the same code, and the interpreter
#: takes seconds a launch).
DRY_RUN = Plan('cpu', kernel_shape=(1, 12, 3, 4), kernel_repeat=2,
               stall_shape=(1, 12, 2, 3), correctness_shape=(1, 12, 3, 5),
               train_shape=(2, 12, 32, 32), paper_shape=(2, 12, 32, 48),
               repeat=1, warmup=1, isolate=False, copy_bytes=1 << 16,
               matmul_size=32, dot_iterations=1, dot_programs_per_sm=1,
               precisions=('tf32', ), check_pixels=1)
#: model -> (raw-spike config, WGSE config), relative to the repository
MODELS = {
    'PSPNet R50-D8': ('configs/pspnet_raw.py', 'configs/pspnet_wgse.py'),
    'SegFormer-B0': ('configs/segformer_b0_raw.py',
                     'configs/segformer_b0_wgse.py'),
}
#: What a report measures the code of, relative to the repository: the
#: package, this measurement wing and the configs.
CODE = ('wgse_mmseg', 'wgse_bench', 'configs')
#: What a section holds until it is measured.
NOT_RUN = dict(status='not run',
               note='not measured: the run stopped before this section')
#: Environment entries that may differ between runs whose sections one
#: report keeps together (:func:`kept_sections`)
_VOLATILE = ('load_average', )


def shape_text(shape: Sequence[int]) -> str:
    """``'4x129x256x512'``."""
    return 'x'.join(map(str, shape))


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
    """The machine record of a report on ``device``, whether Triton runs
    in its interpreter and the measured code's digest (:func:`code_digest`
    of the repository ``root``)."""
    return dict(machine_record(device),
                triton_interpreter=triton_band_networks.interpreting(),
                code=code_digest(root))


class Clock:
    """The time since the report started, its progress lines, and each
    measurement run and recorded."""

    def __init__(self):
        self.start = time.perf_counter()

    def attempt(self, label: str, fn: Callable, *args,
                isolate: bool = False, **kwargs) -> Dict[str, Any]:
        """``fn(*args, **kwargs)`` (a dict; in a fresh process with
        ``isolate``), with ``status`` ``'ok'`` and ``seconds``; ``status``
        ``'failed'`` and ``error`` if it raised."""
        print(f'[gpu_report {self.elapsed():6.1f} s] {label} ...',
              flush=True)
        begin = time.perf_counter()
        try:
            result = run_isolated(fn, *args, **kwargs) if isolate else \
                fn(*args, **kwargs)
        except Exception as error:  # a failed measurement is a finding
            message = error_message(error)
            print(f'    failed: {message.splitlines()[-1]}', flush=True)
            if torch.cuda.is_available():
                torch.cuda.empty_cache()
            return dict(status='failed', error=message,
                        seconds=time.perf_counter() - begin)
        return dict(result, status='ok', seconds=time.perf_counter() - begin)

    def elapsed(self) -> float:
        return time.perf_counter() - self.start


class Run(NamedTuple):
    """What a section's measurement reads: the plan, the clock, the
    repository, the models, the environment and the sections so far."""
    plan: Plan
    clock: Clock
    root: str
    models: Dict[str, Tuple[str, str]]
    environment: Dict[str, Any]
    sections: Dict[str, Dict[str, Any]]
    #: the predictor's answer by precision, asked once a run
    predicted: Dict[str, Dict[str, Any]]

    def prediction(self, precision: str) -> Dict[str, Any]:
        """The predictor's milliseconds at ``precision`` for the kernels'
        shape (:func:`.kernels.predictions`), asked once a run."""
        if precision not in self.predicted:
            self.predicted[precision] = kernels.predictions(
                self.environment, self.plan.kernel_shape, precision)
        return self.predicted[precision]


def status_of(rows: Sequence[Dict]) -> str:
    """``'ok'``/``'failed'`` where every row has it, else ``'partial'``."""
    statuses = {r['status'] for r in rows}
    return statuses.pop() if len(statuses) == 1 else 'partial'


def _ceilings(run: Run) -> Dict[str, Dict[str, Any]]:
    plan = run.plan
    return dict(ceilings=run.clock.attempt(
        'ceilings: clocks, copy, bf16 matrix product',
        ceilings.device_ceilings, plan.copy_bytes, plan.matmul_size,
        plan.device, plan.kernel_repeat))


def _band_kernels(run: Run) -> Dict[str, Dict[str, Any]]:
    plan, rows = run.plan, []
    for precision in plan.precisions:
        found = run.clock.attempt(
            f'band kernels, {precision}, {shape_text(plan.kernel_shape)}',
            kernels.time_kernels, plan.kernel_shape, plan.device, precision,
            plan.kernel_repeat)
        predicted = run.prediction(precision)
        if found['status'] != 'ok':
            rows.append(dict(found, precision=precision, kernel='both'))
            continue
        for row in found['rows']:
            ms = predicted['kernels'].get(row['kernel'])
            rows.append(dict(row, precision=precision, status='ok',
                             predicted_ms=ms, prediction_note=predicted[
                                 'note'], measured_vs_predicted=ratio(
                                     row['median_ms'], ms)))
    return dict(band_kernels=dict(status=status_of(rows), rows=rows,
                                  shape=list(plan.kernel_shape)))


def _wgse(run: Run) -> Dict[str, Dict[str, Any]]:
    plan, text = run.plan, shape_text(run.plan.kernel_shape)
    reference = run.clock.attempt(
        f'WGSE forward+backward, reference, {text}',
        wgse_benchmark.run_worker, ['reference', text, str(plan.kernel_repeat),
                                    '--device', plan.device])
    if reference['status'] == 'ok':
        reference['median_ms'] = 1e3 * reference['median_s']
    rows = [dict(reference, impl='reference', precision='tf32')]
    for impl in wgse_benchmark.available_backends(plan.device):
        for precision in plan.precisions:
            row = run.clock.attempt(
                f'WGSE forward+backward, {impl}, {precision}, {text}',
                kernels.time_pass, impl, precision, plan.kernel_shape,
                plan.device, plan.kernel_repeat)
            if impl == 'triton':
                ms = run.prediction(precision)['kernels'].get('pass')
                row.update(predicted_ms=ms, measured_vs_predicted=ratio(
                    row.get('median_ms'), ms))
            rows.append(dict(row, impl=impl, precision=precision))
    base = rows[0].get('median_ms')
    for row in rows:
        row['time_vs_reference'] = ratio(row.get('median_ms'), base)
    return dict(wgse=dict(status=status_of(rows), shape=list(
        plan.kernel_shape), rows=rows))


def _first_use(run: Run) -> Dict[str, Dict[str, Any]]:
    plan = run.plan
    section = run.clock.attempt(
        f'first-use check of the Triton kernel, T={plan.kernel_shape[1]}',
        measure.check_first_use, plan.kernel_shape[1], plan.device,
        plan.check_pixels)
    if section['status'] == 'ok' and any(
            r['passed'] is False for r in section['rows']):
        section['status'] = 'failed'
        section['error'] = 'failed: ' + ', '.join(
            r['precision'] for r in section['rows'] if r['passed'] is False)
    return dict(first_use=section)


def _stalls(run: Run) -> Dict[str, Dict[str, Any]]:
    plan = run.plan
    return dict(stalls=dict(run.clock.attempt(
        f'one profiled launch of each band kernel, '
        f'{shape_text(plan.stall_shape)}', kernels.profile_launches,
        plan.stall_shape, plan.device, plan.precisions, run.root),
        shape=list(plan.stall_shape)))


def _tensor_cores(run: Run) -> Dict[str, Dict[str, Any]]:
    plan = run.plan
    section = run.clock.attempt(
        'tensor-core products at the band kernels\' tiles',
        ceilings.tensor_core_rates, 32, plan.dot_programs_per_sm,
        plan.dot_iterations, plan.device, plan.kernel_repeat)
    found = run.sections.get('ceilings', {})
    matmul = found.get('matmul_bf16', {}).get('tflops') \
        if found.get('status') == 'ok' else None
    section['rows'] = ceilings.rates_against(section.get('rows', []), matmul)
    if section['status'] == 'ok' and section['rows']:
        section['status'] = status_of(section['rows'])
    return dict(tensor_cores=section)


def _profile(run: Run) -> Dict[str, Dict[str, Any]]:
    """One WGSE pass at the kernels' shape under the profiler, at TF32 and
    bf16; a GPU's only."""
    plan = run.plan
    if not plan.device.startswith('cuda'):
        return dict(profile=dict(status='ok', rows=[], note=(
            f'not run: profiling needs a GPU ({plan.device})')))
    rows = [dict(run.clock.attempt(
        f'profile of one WGSE pass, {precision}, '
        f'{shape_text(plan.kernel_shape)}', wgse_profile.profile_pass,
        plan.kernel_shape, plan.device, precision), precision=precision)
        for precision in plan.precisions]
    return dict(profile=dict(status=status_of(rows),
                             shape=list(plan.kernel_shape), rows=rows))


def _correctness(run: Run) -> Dict[str, Dict[str, Any]]:
    plan = run.plan
    section = run.clock.attempt(
        f'correctness against float64, {shape_text(plan.correctness_shape)}',
        measure.check_correctness, plan.correctness_shape, plan.device)
    if section['status'] == 'ok' and any(
            r['ok'] is False for r in section['rows']):
        section['status'] = 'failed'
        section['error'] = 'raised or outside the tolerance: ' + \
            ', '.join(f"{r['backend']} {r['precision']}"
                      for r in section['rows'] if r['ok'] is False)
    return dict(correctness=dict(section,
                                 shape=list(plan.correctness_shape)))


def model_rows(run: Run, shape: Shape, latency: bool,
               models: Dict[str, Tuple[str, str]], amp: bool = False
               ) -> List[Dict[str, Any]]:
    """Each model's training step (and batch-1 latency) raw and with WGSE
    on a ``(B, T, H, W)`` batch, WGSE's over raw."""
    plan, rows = run.plan, []
    for model, configs in models.items():
        for enhancer, config in zip(('raw', 'WGSE'), configs):
            enhancer += ', AMP' if amp else ''
            row = run.clock.attempt(
                f'{model} {enhancer} step, {shape_text(shape)}',
                measure.segmentation_step, os.path.join(run.root, config),
                shape, plan.repeat, plan.warmup, plan.device, latency, amp,
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


def _segmentation(run: Run) -> Dict[str, Dict[str, Any]]:
    """The ``segmentation`` section and the ``latency`` section its steps
    give."""
    plan = run.plan
    rows = model_rows(run, plan.train_shape, True, run.models)
    if plan.device.startswith('cuda'):  # AMP: fp16 autocast, CUDA only
        rows += model_rows(run, plan.train_shape, False,
                           _pspnet(run.models), amp=True)
    latency = dict(
        status=status_of(rows),
        shape=[1] + list(plan.train_shape[1:]), rows=[
            {k: r.get(k) for k in ('model', 'enhancer', 'status',
                                   'latency_ms', 'added_latency_ms')}
            for r in rows if 'AMP' not in r['enhancer']])
    return dict(segmentation=dict(status=status_of(rows),
                                  shape=list(plan.train_shape), rows=rows),
                latency=latency)


def _paper(run: Run) -> Dict[str, Dict[str, Any]]:
    rows = model_rows(run, run.plan.paper_shape, False, _pspnet(run.models))
    return dict(paper=dict(status=status_of(rows),
                           shape=list(run.plan.paper_shape), rows=rows))


class Step(NamedTuple):
    """Sections measured together: their names, the seconds they are
    expected to take on a GPU with triton's cache empty (what the time
    budget plans with), and the measurement."""
    names: Tuple[str, ...]
    gpu_seconds: float
    measure: Callable[[Run], Dict[str, Dict[str, Any]]]


#: The measurements in the order they run, the most telling first: the
#: device's ceilings, the band kernels and the pass, then the checks, the
#: profiles, and the segmentors if time is left.
STEPS = (
    Step(('ceilings', ), 15, _ceilings),
    Step(('band_kernels', ), 60, _band_kernels),
    Step(('wgse', ), 45, _wgse),
    Step(('first_use', ), 120, _first_use),
    Step(('stalls', ), 60, _stalls),
    Step(('tensor_cores', ), 20, _tensor_cores),
    Step(('profile', ), 10, _profile),
    Step(('correctness', ), 60, _correctness),
    Step(('segmentation', 'latency'), 120, _segmentation),
    Step(('paper', ), 45, _paper),
)
#: Every section of a report, 'targets' last (computed from the others).
SECTIONS = tuple(name for step in STEPS for name in step.names) + (
    'targets', )


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


def _no_room(budget_s: float) -> Dict[str, Any]:
    return dict(status='not run', note=(
        f'not measured: the time budget ({budget_s:.0f} s) left no room for '
        'it; --resume measures it'))


def run_report(plan: Plan, root: str, targets: Targets,
               models: Optional[Dict[str, Tuple[str, str]]] = None,
               earlier: Optional[Dict[str, Any]] = None,
               save: Optional[Callable[[Dict[str, Any]], None]] = None,
               budget_s: Optional[float] = None) -> Dict[str, Any]:
    """Measure every section of the report, most telling first.

    Args:
        plan: the shapes and repeats (``GPU``, or ``DRY_RUN`` on the CPU).
        root: the repository (where the configs of ``models`` are).
        targets: figure -> (at most, aim or ``None``) the figures are
            judged against.
        models: name -> (raw-spike config, WGSE config); default PSPNet
            and SegFormer-B0.
        earlier: a report whose finished sections are kept where it ran
            the same plan and code on the same machine and software (a run
            resumed after a time limit stopped it).
        save: called with the report so far after each section, so that a
            run stopped part-way leaves what it measured.
        budget_s: seconds this run may take: a section starts only where
            the time so far and its expected time (on a GPU) fit, or where
            nothing has been measured yet; the rest are left ``'not run'``
            for a resumed run. ``None``: no limit.

    Returns:
        The JSON-ready report, a dict of ``plan``, ``environment``,
        ``sections``, ``kept`` (the sections taken from ``earlier``) and
        ``seconds``.
    """
    models = MODELS if models is None else models
    clock = Clock()
    print(f'[gpu_report] {plan.device}: {plan._asdict()}', flush=True)
    env = environment(plan.device, root)
    print(' | '.join(f'{k}: {v}' for k, v in env.items()), flush=True)
    finished, why = kept_sections(earlier, plan, env)
    print(f'[gpu_report] {why}', flush=True)
    # a step's sections are kept together or measured together
    kept = [name for step in STEPS
            if all(name in finished for name in step.names)
            for name in step.names]
    sections = {name: dict(NOT_RUN) for name in SECTIONS}
    sections.update({name: earlier['sections'][name] for name in kept})
    report = dict(plan=plan._asdict(), environment=env, sections=sections,
                  kept=kept, seconds=0.0)
    run = Run(plan, clock, root, models, env, sections, {})
    measured = False
    for step in STEPS:
        if step.names[0] in kept:
            continue
        expected = step.gpu_seconds if plan.device.startswith('cuda') else 0
        if budget_s is not None and measured and \
                clock.elapsed() + expected > budget_s:
            print(f'[gpu_report {clock.elapsed():6.1f} s] the budget of '
                  f'{budget_s:.0f} s has no room for {", ".join(step.names)}'
                  ' (--resume measures it)', flush=True)
            sections.update({name: _no_room(budget_s)
                             for name in step.names})
            continue
        sections.update(step.measure(run))
        measured = True
        sections['targets'] = dict(status='ok',
                                   rows=judge(sections, targets))
        report['seconds'] = clock.elapsed()
        if save is not None:
            save(report)
    sections['targets'] = dict(status='ok', rows=judge(sections, targets))
    report['seconds'] = clock.elapsed()
    if save is not None:
        save(report)
    print(f'[gpu_report {clock.elapsed():6.1f} s] done', flush=True)
    return report
