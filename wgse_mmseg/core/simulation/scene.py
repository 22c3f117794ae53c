"""Scene descriptions: which effects a simulation runs, with what parameters.

A scene is a mapping ``effect name -> parameters`` (a dict, or ``None`` /
``{}`` for the effect's defaults), given as a dict or as a JSON or YAML
file holding that mapping, e.g.::

    interpolation: {method: flow}
    shot_noise: {}
    fixed_pattern: {gain_std: 0.05}

Effects not named are off. See docs/simulator.md for every effect.
"""
import os
import os.path as osp
from typing import Any, List, Mapping, Optional, Union

import yaml

from ..limits import (EXCERPT_CHARS, cut, excerpt, load_json_file,
                      read_text_file)
from .effect import EFFECTS, Effect

__all__ = []

_KIND_RANK = dict(light=0, sensor=1, charge=2)


class _SceneLoader(yaml.SafeLoader):
    """YAML's safe loader without aliases (``*name``): a few hundred bytes
    of nested aliases expand into billions of nodes."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None,
                f'found the alias *{cut(event.anchor)}; a scene file may not '
                f'use aliases', event.start_mark)
        return super().compose_node(parent, index)


def read_scene_file(path: Union[str, os.PathLike]) -> dict:
    """The effect mapping a ``.json``, ``.yaml`` or ``.yml`` file holds.

    The file may hold at most :data:`~wgse_mmseg.core.limits.
    TEXT_FILE_LIMIT_BYTES`; YAML aliases are refused.
    """
    path = os.fspath(path)
    ext = osp.splitext(path)[1].lower()
    if ext not in ('.json', '.yaml', '.yml'):
        raise ValueError(
            f'{path}: a scene file must be .json, .yaml or .yml')
    try:
        if ext == '.json':
            scene = load_json_file(path, 'scene file')
        else:
            scene = yaml.load(read_text_file(path, 'scene file'),
                              Loader=_SceneLoader)
    except RecursionError as err:
        raise ValueError(f'{path}: cannot read the scene: nested too '
                         f'deeply') from err
    except (OSError, ValueError, yaml.YAMLError) as err:
        reason = str(err).removeprefix(f'{path}: ')
        raise ValueError(f'{path}: cannot read the scene: '
                         f'{cut(reason, 2 * EXCERPT_CHARS)}') from err
    if scene is None:  # an empty YAML file
        return {}
    if not isinstance(scene, dict):
        raise ValueError(
            f'{path}: a scene file must hold a mapping effect name -> '
            f'parameters, got {type(scene).__name__}')
    return scene


def parse_effects(
        effects: Optional[Union[Mapping[str, Any], str, os.PathLike]]
) -> List[Effect]:
    """Validated effects of a scene, in the order they act.

    Args:
        effects: ``None``, a mapping ``name -> parameters``, or the path of
            a scene file (:func:`read_scene_file`).

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
        source = f'{os.fspath(effects)}: '
        effects = read_scene_file(effects)
    if effects is None:
        return []
    if not isinstance(effects, Mapping):
        raise ValueError(
            f'effects must be a mapping effect name -> parameters, or a '
            f'scene file path; got {type(effects).__name__}')
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
