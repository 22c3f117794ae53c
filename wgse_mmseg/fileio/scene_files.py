"""Scene files: the effect mapping of a simulation, read from JSON or YAML
within :data:`~wgse_mmseg.limits.TEXT_FILE_LIMIT_BYTES` and without YAML
aliases (docs/simulator.md has the effects)."""
import os
import os.path as osp
from typing import Union

import yaml

from ..argument_checks import check_path
from ..errors import EXCERPT_CHARS, cut
from .bounded_reads import load_json_file, read_text_file

__all__ = ['read_scene_file']


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
    """The effect mapping a ``.json``, ``.yaml`` or ``.yml`` file holds,
    checked as the simulator checks its effects.

    The file may hold at most 1 MiB (the limit of every side, marker and
    scene file, docs/security.md); YAML aliases are refused.
    """
    path = os.fspath(check_path('read_scene_file', 'path', path))
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
    from ..core.simulation import parse_effects  # the simulator's torch
    try:
        parse_effects(scene)
    except (TypeError, ValueError) as err:
        raise ValueError(f'{path}: {err}') from err
    return scene
