"""``simulate_spikes``: frames in, a spike stream and what made it out."""
from typing import Any, Dict, Tuple

import numpy as np
import torch

from ...argument_checks import (FLOAT32_RANGE, check_choice, check_integer,
                                check_number)
from ..checks import check_device
from ..constants import READOUT_HZ
from ...limits import MAX_NUM_STEPS, check_allocation
from ..seeding import check_seed
from .effect import SimulationContext
from .fixed_point import CHOICES, MAX_BLOCK_STEPS, Integrator, quantise
from .intensity import frames_to_intensity
from .light import LinearLight
from .scene import parse_effects
from .sensor import SensorMaps

__all__ = ['simulate_spikes']

# A block's float32 charge stays under this, so the allocator reuses it
# instead of mapping fresh pages for each block.
_BLOCK_BYTES = 16 << 20
# Closed-form blocks: long enough to amortise torch's per-op overhead,
# short enough to stay near the cache (and below MAX_LINEAR_BLOCK_STEPS).
_LINEAR_BLOCK = 64


def _output(context: SimulationContext) -> torch.Tensor:
    """``(T, P)`` uint8 spikes. On the CPU NumPy allocates it: NumPy asks
    the kernel for huge pages, and faulting in 4 KiB pages instead can cost
    more than the whole simulation."""
    shape = (context.num_steps, context.num_pixels)
    if context.device.type == 'cpu':
        return torch.from_numpy(np.empty(shape, np.uint8))
    return torch.empty(shape, dtype=torch.uint8, device=context.device)


def simulate_spikes(frames, num_steps: int, threshold: float = 1.0,
                    gain: float = 1.0, effects=None, seed: int = 0,
                    device='cpu',
                    readout_hz: float = READOUT_HZ, backend: str = 'auto'
                    ) -> Tuple[np.ndarray, Dict[str, Any]]:
    """Simulate a spike-camera stream from frames.

    The base model is integrate-and-fire with subtract reset and a random
    initial charge, exact in fixed point, on light resampled linearly from
    the frames; ``effects`` switches on more (docs/simulator.md).

    Args:
        frames: ``(N, H, W)`` or ``(N, H, W, 3)`` RGB, ``uint8`` or float in
            [0, 1]. ``N >= 2`` frames are spread evenly over the stream,
            the first on step 0, the last on step ``T - 1``; ``N = 1`` is a
            still scene.
        num_steps: ``T``, readout steps to simulate.
        threshold: firing threshold, in units of the charge white light
            collects in one step at ``gain = 1``: intensity 1.0 fires on
            average ``gain / threshold`` spikes per step (the REDS
            convention, 0.6, is ``threshold = 1 / 0.6``).
        gain: the ``alpha`` of Eq. 1.
        effects: ``None`` (the base model), a mapping
            ``effect name -> parameters`` or a scene file path.
        seed: non-negative integer; the same seed (and device) gives the
            same stream. Each random stream (initial charge, each effect)
            is derived from it separately.
        device: torch device that runs the simulation.
        readout_hz: readout rate, converting rates in Hz (dark current, hot
            pixels, ``camera_motion`` per second) to steps.
        backend: what integrates: ``'auto'``, ``'torch'`` or
            ``'compiled'`` (a small C kernel); every backend gives the
            same spikes bit for bit.

    Returns:
        ``(spikes, meta)``: ``(T, H, W)`` ``uint8`` 0/1 spikes (NumPy) and a
        dict with the settings, ``resampling`` (``'static'``, ``'linear'``,
        ``'flow'`` or ``'camera_motion'``) and ``effects``: name -> every
        parameter used, for each effect that ran (``{}`` when none).
    """
    entry = 'simulate_spikes'
    check_integer(entry, 'num_steps', num_steps, 1, MAX_NUM_STEPS)
    check_number(entry, 'threshold', threshold, 0, strict_minimum=True,
                 float32=True)
    check_number(entry, 'gain', gain, 0, float32=True)
    seed = check_seed(seed, entry=entry)
    check_number(entry, 'readout_hz', readout_hz, 0, strict_minimum=True,
                 float32=True)
    check_choice(entry, 'backend', backend, CHOICES)
    device = check_device(entry, 'device', device)
    threshold, gain, readout_hz = (float(threshold), float(gain),
                                   float(readout_hz))
    low, high = FLOAT32_RANGE
    if gain and not low <= gain / threshold <= high:
        raise ValueError(
            f'simulate_spikes: gain / threshold (the charge white light '
            f'collects per step, in thresholds) is {gain / threshold:.4g} '
            f'for gain={gain!r} and threshold={threshold!r}; it must be 0 or '
            f'of magnitude in [{low:.4g}, {high:.4g}] (a normal float32)')
    parsed = parse_effects(effects)
    intensity = frames_to_intensity(frames, torch.float32, device)
    count, height, width = intensity.shape
    check_allocation(int(num_steps) * height * width,
                     f'simulate_spikes: the {int(num_steps)} x {height} x '
                     f'{width} uint8 spike stream', 'num_steps or the frame '
                     'size')
    context = SimulationContext(height, width, count, int(num_steps),
                                threshold, gain, readout_hz, seed, device)

    lights = [e.light(intensity, context) for e in parsed
              if e.kind == 'light']
    light = lights[0] if lights else LinearLight(intensity, context.num_steps)
    maps = SensorMaps(context)
    for effect in parsed:
        if effect.kind == 'sensor':
            effect.apply(maps, context)
    noises = [e for e in parsed if e.kind == 'charge']
    for noise in noises:
        noise.start(maps, context)

    closed_form = light.linear and not noises
    block = _LINEAR_BLOCK if closed_form else max(1, min(
        MAX_BLOCK_STEPS, _BLOCK_BYTES // (4 * context.num_pixels)))
    integrator = Integrator(context.num_pixels, seed, device, block, backend)
    spikes = _output(context)
    segment = linear = None
    for start, stop in light.blocks(block):
        out = spikes[start:stop]
        if closed_form:
            if light.segment(start) != segment:
                segment = light.segment(start)
                first, last = light.segment_frames(segment)
                linear = integrator.linear_charge(
                    maps.charge(first),
                    None if last is first else maps.charge(last),
                    light.denominator)
            if linear is not None:
                integrator.linear(linear, light.weights(start, stop), out)
                continue
        charge = maps.charge(light.intensity(start, stop))
        for noise in noises:
            charge = noise(charge)
        integrator.per_step(*quantise(charge), out)

    meta = dict(model='integrate-and-fire', num_steps=context.num_steps,
                threshold=threshold, gain=gain, seed=seed,
                readout_hz=readout_hz, num_frames=count, height=height,
                width=width, resampling=light.resampling,
                effects={e.name: e.params for e in parsed})
    return spikes.view(-1, height, width).cpu().numpy(), meta
