"""Spike-camera simulation: integrate-and-fire on light per readout step.

:func:`simulate_spikes` turns ``(N, H, W[, 3])`` frames into a ``(T, H, W)``
spike stream. The base model (Eq. 1 of the paper) integrates
``gain * I(t)`` per readout step (25 us at 40 kHz) and fires a spike at each
multiple of the threshold, with subtract reset (no charge is lost) and a
random initial charge; intensity 1.0 fires ``gain / threshold`` spikes per
step on average. Effects, each off unless a scene names it, add frame
interpolation along optical flow or camera motion, shot noise, dark
current, fixed-pattern mismatch, hot pixels and readout jitter.

Modules, one concept each:

- :mod:`.intensity`: frames to intensity in [0, 1]
- :mod:`.light`: light per step; the base model's linear resampling
- :mod:`.interpolation`, :mod:`.camera_motion`: the light effects
  (with :mod:`.warp`)
- :mod:`.sensor`: the sensor's per-pixel response and its effects
- :mod:`.noise`: per-step charge noise effects
- :mod:`.fixed_point`: exact integrate-and-fire in fixed point
- :mod:`.effect`, :mod:`.scene`: effect registry, scene descriptions
- :mod:`.simulator`: :func:`simulate_spikes`

docs/simulator.md describes the model, every effect and its calibrated
defaults, with sources.
"""
from . import interpolation, noise, sensor  # noqa: F401
from .camera_motion import trajectory_source_maps
from .effect import EFFECTS, register_effect
from .fixed_point import initial_charge
from .intensity import frames_to_intensity
from .scene import parse_effects
from .simulator import simulate_spikes

__all__ = ['simulate_spikes']
