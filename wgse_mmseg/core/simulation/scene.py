"""Scene descriptions: which effects a simulation runs, with what parameters.

A scene is a mapping ``effect name -> parameters`` (a dict, or ``None`` /
``{}`` for the effect's defaults), given as a dict (a JSON or YAML scene
file's, read by :func:`wgse_mmseg.fileio.read_scene_file`), e.g.::

    interpolation: {method: flow}
    shot_noise: {}
    fixed_pattern: {gain_std: 0.05}

Effects not named are off. See docs/simulator.md for every effect.
"""
import os
from typing import Any, List, Mapping, Optional

from ...errors import excerpt
from .effect import EFFECTS, Effect

__all__ = []

_KIND_RANK = dict(light=0, sensor=1, charge=2)


def parse_effects(
        effects: Optional[Mapping[str, Any]]
) -> List[Effect]:
    """Validated effects of a scene, in the order they act.

    Args:
        effects: ``None`` or a mapping ``name -> parameters`` (a scene
            file's, :func:`wgse_mmseg.fileio.read_scene_file`).

    Returns:
        One instance per named effect: the light effect first, then the
        sensor effects (by name: they commute), then the charge effects in
        their fixed ``order``.

    Raises:
        ValueError: for an unknown effect (listing the known ones), bad
            parameters, or both light effects at once.
    """
    source = ''
    if isinstance(effects, (str, os.PathLike)):
        raise TypeError(
            f'effects must be a mapping effect name -> parameters; read a '
            f'scene file with wgse_mmseg.fileio.read_scene_file, got '
            f'{excerpt(os.fspath(effects))}')
    if effects is None:
        return []
    if not isinstance(effects, Mapping):
        raise ValueError(
            f'effects must be a mapping effect name -> parameters; got '
            f'{type(effects).__name__}')
    unknown = sorted(map(str, set(effects) - set(EFFECTS)))
    if unknown:
        raise ValueError(
            f'{source}unknown effect(s) {excerpt(unknown)}; known: '
            f'{sorted(EFFECTS)}')
    try:
        parsed = [EFFECTS[name](params) for name, params in effects.items()]
    except ValueError as err:
        raise ValueError(f'{source}{err}') from err
    lights = [effect.name for effect in parsed if effect.kind == 'light']
    if len(lights) > 1:
        raise ValueError(
            f'{source}{lights} both decide how frames become light; name '
            f'one (interpolation for video, camera_motion for a still)')
    return sorted(parsed, key=lambda e: (_KIND_RANK[e.kind],
                                         getattr(e, 'order', 0), e.name))
