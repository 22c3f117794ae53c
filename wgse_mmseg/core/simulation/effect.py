"""Simulator effects: the base classes, their parameters and the registry.

An effect is one optional piece of the simulation, configured by a dict of
parameters and off unless a scene names it. There are three kinds, by the
stage of the simulation they act on:

``LightEffect``
    How the input frames become light per readout step (frame interpolation,
    camera motion). At most one runs; without one, the base model's
    resampling does (:mod:`.light`).
``SensorEffect``
    A fixed per-pixel property of the sensor (gain and threshold mismatch,
    dark current, hot pixels), folded into :class:`~.sensor.SensorMaps`
    before the first step. They commute, so their order does not matter.
``ChargeEffect``
    A random change of the charge collected in each step (readout jitter,
    shot noise), applied per block of steps in the order of ``order``.

Each effect draws its random numbers from its own generator
(:meth:`SimulationContext.generator`), seeded by
:func:`~wgse_mmseg.core.seeding.derive_seed` from the clip's seed and the
effect's name, so switching one effect on or off never changes another's
draws.
"""
from dataclasses import dataclass
from typing import Any, ClassVar, Dict, Mapping, Optional, Sequence, Type

import torch

from ... import argument_checks
from ...argument_checks import ArgumentError, is_number
from ...errors import excerpt
from ..seeding import derive_seed

__all__ = []


#: the entry point errors about effect parameters name
_EFFECTS = 'effects'


@dataclass(frozen=True)
class SimulationContext:
    """What every effect may read about the simulation it is part of.

    ``threshold`` and ``gain`` are the nominal (sensor-wide) values;
    ``readout_hz`` converts rates in Hz to charge per readout step.
    """
    height: int
    width: int
    num_frames: int
    num_steps: int
    threshold: float
    gain: float
    readout_hz: float
    seed: int
    device: torch.device

    @property
    def num_pixels(self) -> int:
        return self.height * self.width

    def generator(self, key: str,
                  seed: Optional[int] = None) -> torch.Generator:
        """A generator on ``device`` for the random stream ``key``.

        ``seed`` overrides the clip's seed (a sensor's fixed pattern is
        seeded by the sensor, not by the clip).
        """
        generator = torch.Generator(device=self.device)
        generator.manual_seed(
            derive_seed(self.seed if seed is None else seed, key))
        return generator


def check_number(effect: str, name: str, value: Any,
                 low: Optional[float] = None, high: Optional[float] = None,
                 low_open: bool = False) -> float:
    """A finite real number in ``[low, high]`` (``(low, high]`` if
    ``low_open``), 0 or a normal float32 (it enters float32 arithmetic), as
    a float."""
    argument_checks.check_number(_EFFECTS, f'{effect}.{name}', value, low,
                                 high, strict_minimum=low_open, float32=True)
    return float(value)


def check_choice(effect: str, name: str, value: Any,
                 choices: Sequence[str]) -> str:
    """One of ``choices``."""
    return argument_checks.check_choice(_EFFECTS, f'{effect}.{name}', value,
                                        choices)


def check_pair(effect: str, name: str, value: Any) -> list:
    """Two finite numbers, as a list (JSON's form of a pair)."""
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and
            all(is_number(v) for v in value)):
        raise ArgumentError(_EFFECTS, f'{effect}.{name}',
                            '(a, b), each a finite number', value)
    return [float(v) for v in value]


class Effect:
    """One optional piece of the simulation, configured by parameters.

    Subclasses set ``name`` (the scene's key), ``defaults`` (every
    parameter, with its default) and override :meth:`check` to validate
    values. ``params`` then holds every parameter, defaults filled in, in
    plain JSON types: it is what the output's metadata records.
    """
    name: ClassVar[str] = ''
    kind: ClassVar[str] = ''
    defaults: ClassVar[Dict[str, Any]] = {}

    def __init__(self, params: Optional[Mapping[str, Any]] = None):
        if params is None:
            params = {}
        if not isinstance(params, Mapping):
            raise ValueError(
                f'{self.name}: parameters must be a mapping (or null for '
                f'the defaults), got {excerpt(params)}')
        unknown = sorted(map(str, set(params) - set(self.defaults)))
        if unknown:
            raise ValueError(
                f'{self.name}: unknown parameter(s) {excerpt(unknown)}; '
                f'known: {sorted(self.defaults)}')
        self.params = self.check({**self.defaults, **params})

    def check(self, params: Dict[str, Any]) -> Dict[str, Any]:
        """Validate ``params`` (all keys present); return them normalised."""
        return params

    def __repr__(self):
        return f'{self.__class__.__name__}({self.params})'


class LightEffect(Effect):
    """Turns the ``(N, H, W)`` input intensity into light per step."""
    kind = 'light'

    def light(self, intensity: torch.Tensor, context: SimulationContext):
        """Return a :class:`~.light.Light` for ``intensity`` (float32 in
        [0, 1], on ``context.device``)."""
        raise NotImplementedError


class SensorEffect(Effect):
    """A fixed per-pixel property of the sensor."""
    kind = 'sensor'

    def apply(self, maps, context: SimulationContext) -> None:
        """Fold this effect into ``maps`` (a :class:`~.sensor.SensorMaps`)."""
        raise NotImplementedError


class ChargeEffect(Effect):
    """A random change of the charge collected per step.

    One instance serves one simulation: :meth:`start` is called once, then
    :meth:`__call__` once per block of steps, in time order, so an effect
    may carry state from block to block.
    """
    kind = 'charge'
    order: ClassVar[int] = 0

    def start(self, maps, context: SimulationContext) -> None:
        """Prepare for a simulation (draw generators, initial state)."""

    def __call__(self, charge: torch.Tensor) -> torch.Tensor:
        """``(K, P)`` float32 charge of the next ``K`` steps, in thresholds
        of each pixel, to the same with this effect applied."""
        raise NotImplementedError


EFFECTS: Dict[str, Type[Effect]] = {}


def register_effect(cls: Type[Effect]) -> Type[Effect]:
    """Class decorator: make ``cls`` available to scenes as ``cls.name``."""
    if cls.kind not in ('light', 'sensor', 'charge') or not cls.name:
        raise TypeError(
            f'{cls.__name__} must subclass LightEffect, SensorEffect or '
            f'ChargeEffect and set a name')
    if cls.name in EFFECTS:
        raise ValueError(f'an effect named {cls.name!r} is already '
                         f'registered ({EFFECTS[cls.name].__name__})')
    EFFECTS[cls.name] = cls
    return cls
