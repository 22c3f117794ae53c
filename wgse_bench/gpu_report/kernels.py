"""The Triton band kernels and the WGSE pass around them, timed and
profiled: each kernel's launch over a batch's coefficients, the whole
forward+backward per backend and precision, each beside the resources
tool's prediction where it gives one, and one profiled launch of each
kernel with its warps' stall reasons (Nsight Compute where the machine
has ``ncu``, else the launch's time from torch's profiler)."""
import csv
import os
import re
import shutil
import statistics
import subprocess
import sys
from typing import Any, Callable, Dict, List, Optional, Sequence

import torch

from wgse_mmseg.core.wavelets import band_lengths
from wgse_mmseg.core.wgse import (WGSE, triton_band_networks,
                                  triton_launch_choices)

from ..timing import time_calls
from .measure import error_message, precision_of, spikes_like

__all__ = []

#: the band kernels, as their launches are named
KERNELS = ('band_forward', 'band_backward')
#: the predictor this report sets its timings beside: module, function
PREDICTOR = ('wgse_bench.kernel_prediction', 'predict_band_kernels')
#: Nsight Compute's sections one profiled launch collects: the share of
#: the peaks reached, why warps stalled, how often the schedulers issued
NCU_SECTIONS = ('SpeedOfLight', 'WarpStateStats', 'SchedulerStats')
_STALL = re.compile(
    r'smsp__average_warps_issue_stalled_(\w+)_per_issue_active\.ratio')
_NCU_FIGURES = dict(
    ms='gpu__time_duration.sum',
    issue_active_pct='smsp__issue_active.avg.pct_of_peak_sustained_active',
    sm_throughput_pct='sm__throughput.avg.pct_of_peak_sustained_elapsed')
_TO_MS = {'nsecond': 1e-6, 'usecond': 1e-3, 'msecond': 1.0, 'second': 1e3}


def band_problem(shape: Sequence[int], device: str) -> Dict[str, Any]:
    """What the band kernels read for WGSE's default networks on a
    ``(B, T, H, W)`` batch: ``coeffs`` ``(B, C, H * W)`` (random, ``C`` the
    bands' coefficients of ``T`` steps), the stacked parameters
    (``inputs``), an output gradient ``grad_out`` like ``coeffs`` and the
    band ``lengths``."""
    torch.manual_seed(0)
    model = WGSE().to(device)
    batch, steps, height, width = shape
    lengths = band_lengths(steps, model.wavelet, model.level, model.mode)
    generator = torch.Generator().manual_seed(3)
    coeffs, grad_out = (torch.randn(batch, sum(lengths), height * width,
                                    generator=generator).to(device)
                        for _ in range(2))
    params = [t.detach() for net in model.band_networks
              for conv, _ in net.layers() for t in (conv.weight, conv.bias)]
    return dict(coeffs=coeffs, grad_out=grad_out, lengths=lengths,
                inputs=triton_band_networks.band_kernel_inputs(lengths,
                                                               params))


def kernel_launches(problem: Dict[str, Any], precision: str
                    ) -> Dict[str, Callable[[], Any]]:
    """Per band kernel, a function that launches it once over
    :func:`band_problem`'s ``problem`` with products of ``precision``, as a
    training pass does (the backward from the forward's mask, no input
    gradient)."""
    tbn = triton_band_networks
    coeffs, inputs = problem['coeffs'], problem['inputs']
    forward = triton_launch_choices.FORWARD_CONFIGS[0]
    _, positive = tbn.launch_forward(forward, coeffs, inputs, precision)
    d3 = tbn.relu_gradient(problem['grad_out'], positive)
    slots = tbn.backward_slots(coeffs.device, len(problem['lengths']))
    backward = triton_launch_choices.backward_configs(False, precision)[0]
    return dict(
        band_forward=lambda: tbn.launch_forward(forward, coeffs, inputs,
                                                precision),
        band_backward=lambda: tbn.launch_backward(
            backward, coeffs, d3, None, inputs, precision, slots))


def predictions(environment: Dict[str, Any], shape: Sequence[int],
                precision: str) -> Dict[str, Any]:
    """The predictor's milliseconds of each band kernel (and of the pass,
    ``'pass'``, where it gives one) on the report's GPU for a ``(B, T, H,
    W)`` batch at ``precision``: ``{'kernels': {name: ms}, 'note'}``, the
    kernels empty and the note saying why where :data:`PREDICTOR` is absent
    or gives nothing this report reads (a mapping of kernel to
    milliseconds, or to a dict holding ``predicted_ms``, or rows holding
    ``kernel`` and ``predicted_ms``)."""
    module, name = PREDICTOR
    try:
        predict = getattr(__import__(module, fromlist=[name]), name, None)
    except ImportError as error:
        predict, absent = None, error_message(error)
    else:
        absent = f'{module} has no {name}'
    if predict is None:
        return dict(kernels={}, note=f'no prediction: {absent}')
    try:
        found = predict(environment=environment, shape=tuple(shape),
                        precision=precision)
    except Exception as error:  # noqa: BLE001 - recorded, not fatal
        return dict(kernels={}, note=f'no prediction: {name}(environment, '
                    f'shape, precision) raised {error_message(error)}')
    if isinstance(found, dict):
        found = [dict(value, kernel=key) if isinstance(value, dict) else
                 dict(kernel=key, predicted_ms=value)
                 for key, value in found.items()]
    kernels = {}
    for row in found if isinstance(found, (list, tuple)) else []:
        value = row.get('predicted_ms') if isinstance(row, dict) else None
        if isinstance(value, (int, float)) and \
                row.get('precision', precision) == precision:
            kernels[str(row.get('kernel'))] = float(value)
    return dict(kernels=kernels, note=None if kernels else
                f'no prediction: {name} gave none this report reads')


def time_kernels(shape: Sequence[int], device: str, precision: str,
                 repeat: int) -> Dict[str, Any]:
    """Each band kernel's launch over a ``(B, T, H, W)`` batch's
    coefficients at ``precision``: ``{'rows': [{'kernel', 'median_ms',
    'min_ms', 'max_ms', 'launch'}]}``, ``repeat`` timed launches after two
    untimed ones on a GPU (the first compiles; the interpreter has nothing
    to warm up)."""
    problem = band_problem(shape, device)
    configs = dict(
        band_forward=triton_launch_choices.FORWARD_CONFIGS[0],
        band_backward=triton_launch_choices.backward_configs(False,
                                                             precision)[0])
    rows, warmup = [], 2 if problem['coeffs'].is_cuda else 0
    for kernel, launch in kernel_launches(problem, precision).items():
        wall = [1e3 * s for s in time_calls(launch, device, repeat,
                                            warmup).wall]
        rows.append(dict(kernel=kernel, median_ms=statistics.median(wall),
                         min_ms=min(wall), max_ms=max(wall),
                         launch=configs[kernel].name))
    return dict(rows=rows, coefficients=sum(problem['lengths']))


def time_pass(backend: str, precision: str, shape: Sequence[int],
              device: str, repeat: int) -> Dict[str, Any]:
    """WGSE's forward+backward with ``backend`` at ``precision`` (TF32 for
    the backward too; autocast for the forward) on a ``(B, T, H, W)`` batch,
    the output gradient a fixed random tensor: ``median_ms``, ``min_ms``,
    ``max_ms`` of ``repeat`` passes after two untimed ones on a GPU (the
    first compiles and checks, the second measures ``peak_mib``: growth of
    CUDA memory allocated in one pass; ``None`` on the CPU) and ``backend``
    (what ran)."""
    torch.manual_seed(0)
    model = WGSE(backend=backend).to(device)
    spikes = spikes_like(shape, device)
    grad = torch.randn(tuple(shape), generator=torch.Generator().manual_seed(
        2)).to(device)  # WGSE's output is shaped as its input

    def one_pass():
        model.zero_grad(set_to_none=True)
        with precision_of(precision, spikes.device.type):
            out = model(spikes)
            with torch.autocast(spikes.device.type, enabled=False):
                out.backward(grad)

    peak = None
    if spikes.is_cuda:
        one_pass()  # compiles and checks
        torch.cuda.synchronize()
        torch.cuda.reset_peak_memory_stats()
        before = torch.cuda.memory_allocated()
        one_pass()
        peak = (torch.cuda.max_memory_allocated() - before) / 2**20
    wall = [1e3 * s for s in time_calls(one_pass, device, repeat, 0).wall]
    return dict(median_ms=statistics.median(wall), min_ms=min(wall),
                max_ms=max(wall), peak_mib=peak,
                backend=model.backend_in_use)


def launch_each_kernel(shape: Sequence[int], device: str,
                       precisions: Sequence[str]) -> List[str]:
    """One launch of each band kernel at each of ``precisions``, in that
    order (what a profiler run records); returns ``'kernel precision'`` of
    each."""
    problem = band_problem(shape, device)
    done = []
    for precision in precisions:
        for kernel, launch in kernel_launches(problem, precision).items():
            with torch.profiler.record_function(f'{kernel} {precision}'):
                launch()
            done.append(f'{kernel} {precision}')
    if problem['coeffs'].is_cuda:
        torch.cuda.synchronize()
    return done


def parse_ncu_csv(text: str) -> List[Dict[str, Any]]:
    """Nsight Compute's ``--csv --page raw`` output (other lines ignored)
    as one row per profiled launch, in launch order: ``kernel``, ``ms``,
    ``issue_active_pct``, ``sm_throughput_pct`` (``None`` where absent)
    and ``stalls``: reason -> warps stalled for it per issued instruction
    (``smsp__average_warps_issue_stalled_*_per_issue_active``)."""
    table = list(csv.reader(line for line in text.splitlines()
                            if line.startswith('"')))
    if not table or 'Kernel Name' not in table[0]:
        return []
    header, rows = table[0], []
    units = next((r for r in table[1:] if r and not r[0].isdigit()), [])
    unit = dict(zip(header, units))

    def number(cells: Dict[str, str], key: str) -> Optional[float]:
        try:
            return float(cells.get(key, '').replace(',', ''))
        except ValueError:
            return None

    for cells in (dict(zip(header, r)) for r in table[1:]
                  if r and r[0].isdigit()):
        row = dict(kernel=cells['Kernel Name'])
        for name, key in _NCU_FIGURES.items():
            row[name] = number(cells, key)
        if row['ms'] is not None:
            row['ms'] *= _TO_MS.get(unit.get(_NCU_FIGURES['ms']), 1e-6)
        row['stalls'] = {match.group(1): number(cells, key)
                         for key in header for match in [_STALL.match(key)]
                         if match and number(cells, key) is not None}
        rows.append(row)
    return rows


def _launch_program(shape: Sequence[int], device: str,
                    precisions: Sequence[str]) -> List[str]:
    """The command line of a fresh Python process that runs
    :func:`launch_each_kernel` (the program a profiler is wrapped
    around)."""
    call = (f'launch_each_kernel({list(shape)}, {device!r}, '
            f'{list(precisions)})')
    return [sys.executable, '-c', 'from wgse_bench.gpu_report.kernels '
            f'import launch_each_kernel; {call}']


def _ncu_launches(ncu: str, shape: Sequence[int], device: str,
                  precisions: Sequence[str], root: str,
                  timeout_s: float) -> List[Dict[str, Any]]:
    """:func:`parse_ncu_csv`'s rows of ``ncu`` around
    :func:`launch_each_kernel` (clocks left as they are), each with its
    ``precision``."""
    command = [ncu, '--clock-control', 'none', '--target-processes', 'all',
               '--kernel-name', 'regex:band_', '--launch-count',
               str(len(KERNELS) * len(precisions)), '--csv', '--page', 'raw']
    for section in NCU_SECTIONS:
        command += ['--section', section]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [root] + os.environ.get('PYTHONPATH', '').split(os.pathsep)))
    proc = subprocess.run(command + _launch_program(shape, device,
                                                    precisions),
                          capture_output=True, text=True, cwd=root, env=env,
                          timeout=timeout_s)
    rows = parse_ncu_csv(proc.stdout)
    if proc.returncode != 0 or len(rows) != len(KERNELS) * len(precisions):
        raise RuntimeError(f'ncu (exit {proc.returncode}) profiled '
                           f'{len(rows)} launches: ' +
                           (proc.stderr + proc.stdout)[-1500:])
    order = [p for p in precisions for _ in KERNELS]
    return [dict(row, precision=p) for row, p in zip(rows, order)]


def _profiler_launches(shape: Sequence[int], device: str,
                       precisions: Sequence[str]) -> List[Dict[str, Any]]:
    """Each launch of :func:`launch_each_kernel` under torch's profiler:
    ``kernel``, ``precision``, ``ms`` (the device kernel's time on CUDA,
    the launch's host time on the CPU) and no ``stalls``."""
    if device.startswith('cuda'):  # compiles, outside the profile
        launch_each_kernel(shape, device, precisions)
    activities = [torch.profiler.ProfilerActivity.CPU]
    if device.startswith('cuda'):
        activities.append(torch.profiler.ProfilerActivity.CUDA)
    with torch.profiler.profile(activities=activities) as profiler:
        labels = launch_each_kernel(shape, device, precisions)
    events = profiler.events()
    if device.startswith('cuda'):
        # the kernels themselves, not the labels' ranges on the GPU's line
        times = [e.time_range.elapsed_us() / 1e3 for e in events
                 if e.device_type == torch.autograd.DeviceType.CUDA
                 and e.name.startswith('band_') and ' ' not in e.name]
    else:
        times = [next(e.time_range.elapsed_us() / 1e3 for e in events
                      if e.name == label) for label in labels]
    if len(times) != len(labels):
        raise RuntimeError(f"torch's profiler recorded {len(times)} band "
                           f'kernel launches, not {len(labels)}')
    return [dict(kernel=label.split()[0], precision=label.split()[1],
                 ms=ms, stalls=None) for label, ms in zip(labels, times)]


def profile_launches(shape: Sequence[int], device: str,
                     precisions: Sequence[str], root: str,
                     timeout_s: float = 240) -> Dict[str, Any]:
    """One profiled launch of each band kernel at each of ``precisions``
    on a ``(B, T, H, W)`` batch: ``{'tool', 'rows', 'note'}``, the rows
    :func:`parse_ncu_csv`'s (with ``precision``) where ``ncu`` is on the
    PATH and profiles them (in a fresh process from the repository
    ``root``), else torch's profiler's (no stall reasons; ``note`` says
    why)."""
    ncu = shutil.which('ncu') if device.startswith('cuda') else None
    note = None
    if ncu:
        try:
            return dict(tool='ncu', rows=_ncu_launches(
                ncu, shape, device, precisions, root, timeout_s), note=None)
        except (RuntimeError, OSError, subprocess.SubprocessError) as error:
            note = f'ncu failed ({error_message(error)})'
    note = note or ('no ncu on the PATH' if device.startswith('cuda')
                    else f'Nsight Compute profiles CUDA, not {device}')
    return dict(tool='torch.profiler', note=note + ": torch's profiler "
                'gives each launch its time, no stall reasons',
                rows=_profiler_launches(shape, device, precisions))
