"""The spike simulator's throughput and spike files' load time.

What ``tools/analysis_tools/benchmark_simulator.py`` runs (its docstring
says what the two tables hold; docs/simulator.md has the figures).
:func:`simulator_rows` and :func:`load_rows` take the tool's parsed
arguments (``height``, ``width``, ``steps``, ``frames``, ``repeat``,
``device``, ``threads``, ``load_shape``) and return the table's lines.
Needs the core alone, nothing of OpenMMLab.
"""
import os.path as osp
import statistics
import tempfile
from typing import Callable, List, NamedTuple

import cv2
import numpy as np

from wgse_mmseg.core.constants import REDS_THRESHOLD
from wgse_mmseg.fileio.spike_files import (SPIKE_EXTENSIONS, load_spikes,
                                           save_spikes)
from wgse_mmseg.core.simulation import fixed_point, simulate_spikes

from .machine import machine_record
from .timing import time_calls


def _numpy_step_loop(frames: np.ndarray, num_steps: int, threshold: float,
                     seed: int) -> np.ndarray:
    """The plain reference: integrate-and-fire one readout step at a time.

    ``(N, H, W)`` float frames in [0, 1] (linearly interpolated when
    ``N > 1``), gain 1, subtract reset, uniform initial charge; float64.
    Returns ``(T, H, W)`` uint8 spikes.
    """
    intensity = frames.astype(np.float64)
    count = intensity.shape[0]
    charge = np.random.default_rng(seed).random(intensity.shape[1:]) * \
        threshold
    spikes = np.empty((num_steps, ) + intensity.shape[1:], np.uint8)
    positions = np.linspace(0, count - 1, num_steps)
    for step in range(num_steps):
        if count == 1:
            light = intensity[0]
        else:
            k = min(int(positions[step]), count - 2)
            w = positions[step] - k
            light = (1 - w) * intensity[k] + w * intensity[k + 1]
        charge += light
        fired = charge >= threshold
        charge -= threshold * fired
        spikes[step] = fired
    return spikes


class _Timing(NamedTuple):
    wall: float  # median wall seconds
    cpu: float  # median CPU seconds of this process (all its threads)
    result: object  # the last call's


def _median_time(run: Callable[[], object], repeat: int,
                 device: str) -> _Timing:
    """Median wall and CPU time of ``repeat`` calls after a warm-up
    (:func:`~wgse_bench.timing.time_calls`)."""
    timings = time_calls(run, device, repeat, warmup=1)
    return _Timing(statistics.median(timings.wall),
                   statistics.median(timings.cpu), timings.result)


def _compiled_runs(device: str) -> bool:
    """Whether ``'auto'`` integrates with the compiled kernel on
    ``device``."""
    return fixed_point.resolve_backend('auto', device) == 'compiled'


def header(args) -> List[str]:
    kernel = ('compiled CPU kernel' if _compiled_runs(args.device) else
              'torch path')
    machine = machine_record(args.device)
    return [
        f"machine: {machine['cpu']}, {machine['cpu_count']} logical CPUs, "
        f"{machine['platform']}" + (f", {machine['gpu']}"
                                    if 'gpu' in machine else ''),
        f"python {machine['python']}, torch {machine['torch']}, "
        f"numpy {machine['numpy']}, opencv {machine['opencv']}; torch "
        f"threads {machine['torch_threads']}; device {args.device}",
        f'sample {args.height}x{args.width}, T={args.steps}, threshold '
        f'1/0.6; median of {args.repeat} runs; integrate-and-fire: '
        f'{kernel}',
    ]


def simulator_rows(args, still: np.ndarray, video: np.ndarray) -> List[str]:
    """The throughput table."""
    inputs = dict(still=still, video=video)
    reference = {}
    rows = []
    for name, frames in inputs.items():
        timing = _median_time(
            lambda: _numpy_step_loop(frames, args.steps, REDS_THRESHOLD, 0),
            args.repeat, 'cpu')
        reference[name] = timing.wall
        rows.append(('NumPy step loop', name, timing, timing.result))
    cases = [
        ('base model', 'still', None),
        ('base model', 'video', None),
    ]
    if _compiled_runs(args.device):
        cases += [('base model, torch path', 'still', None),
                  ('base model, torch path', 'video', None)]
    cases += [
        ('+ interpolation (flow)', 'video',
         dict(interpolation=dict(method='flow'))),
        ('+ camera_motion', 'still', dict(camera_motion={})),
        ('+ shot_noise', 'still', dict(shot_noise={})),
        ('+ dark_current', 'still', dict(dark_current={})),
        ('+ fixed_pattern', 'still', dict(fixed_pattern={})),
        ('+ hot_pixels', 'still', dict(hot_pixels={})),
        ('+ jitter', 'still', dict(jitter={})),
        ('all sensor + charge effects', 'still',
         dict(shot_noise={}, dark_current={}, fixed_pattern={},
              hot_pixels={}, jitter={})),
    ]
    for case, name, effects in cases:
        backend = 'torch' if case.endswith('torch path') else 'auto'
        timing = _median_time(
            lambda: simulate_spikes(inputs[name], args.steps, REDS_THRESHOLD,
                                    effects=effects, seed=0,
                                    device=args.device, backend=backend),
            args.repeat, args.device)
        rows.append((case, name, timing, timing.result[0]))
    base = {name: spikes for case, name, _, spikes in rows
            if case == 'base model'}
    for case, name, _, spikes in rows:
        if case.endswith('torch path') and not np.array_equal(
                spikes, base[name]):
            raise RuntimeError(f'{name}: the torch path and the compiled '
                               f'kernel simulated different spikes')
    pixel_steps = args.height * args.width * args.steps
    lines = [f'{"case":29s} {"input":6s} {"wall ms":>9s} {"cpu ms":>9s} '
             f'{"Mpx-steps/s":>12s} {"vs NumPy loop":>14s} '
             f'{"spike rate":>11s}']
    for case, name, timing, spikes in rows:
        lines.append(
            f'{case:29s} {name:6s} {timing.wall * 1e3:9.1f} '
            f'{timing.cpu * 1e3:9.1f} '
            f'{pixel_steps / timing.wall / 1e6:12.1f} '
            f'{reference[name] / timing.wall:13.2f}x '
            f'{spikes.mean():11.4f}')
    return lines


def load_rows(args, still: np.ndarray) -> List[str]:
    """The load-time table: each format against simulating the sample."""
    steps, height, width = args.load_shape
    frame = cv2.resize(still[0], (width, height),
                       interpolation=cv2.INTER_LINEAR)[None]
    simulated = _median_time(
        lambda: simulate_spikes(frame, steps, REDS_THRESHOLD, seed=0,
                                device=args.device), args.repeat,
        args.device)
    spikes = simulated.result[0]
    lines = [f'{"T x H x W = " + "x".join(map(str, args.load_shape)):29s} '
             f'{"MB":>6s} {"wall ms":>9s} {"cpu ms":>9s} '
             f'{"vs simulating":>14s}',
             f'{"simulate (base, still)":29s} {"":6s} '
             f'{simulated.wall * 1e3:9.1f} {simulated.cpu * 1e3:9.1f} '
             f'{1:13.2f}x']
    with tempfile.TemporaryDirectory() as tmp:
        for ext in SPIKE_EXTENSIONS:
            path = osp.join(tmp, 'sample' + ext)
            save_spikes(path, spikes)
            load = _median_time(lambda: load_spikes(path, height, width),
                                args.repeat, 'cpu')
            if not np.array_equal(load.result, spikes):
                raise RuntimeError(f'{ext}: the loaded sample differs')
            lines.append(f'load {ext:24s} {osp.getsize(path) / 1e6:6.1f} '
                         f'{load.wall * 1e3:9.1f} {load.cpu * 1e3:9.1f} '
                         f'{simulated.wall / load.wall:13.2f}x')
    return lines
