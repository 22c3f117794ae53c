"""T in one place: a config's ``num_steps`` reaches every field built from it.

The shipped configs set ``num_steps`` (T) once, in the dataset base, and
derive the loader's window, the data preprocessor's check, the datasets'
``num_steps`` and the backbone's ``in_channels`` from it when mmengine parses
the base. A config that inherits one and sets ``num_steps = 41`` changes the
variable but not what the base already computed from it (mmengine resolves
``{{_base_.num_steps}}`` and plain variables as each file is read).

:func:`apply_num_steps` closes that gap when the config is built: the shipped
configs' runner (:class:`~wgse_mmseg.engine.SpikeRunner`, so MMSeg's own
``tools/train.py`` too) and :func:`~wgse_mmseg.utils.config.load_config`
call it. The T fields are every ``num_steps`` under ``model``,
``train_dataloader``, ``val_dataloader`` and ``test_dataloader`` (pipeline
steps, datasets, the data preprocessor, reconstruction models) and, where the
data preprocessor takes ``num_steps``, ``model.backbone.in_channels`` (the
enhancers keep T channels). If they all hold one value, made from one T,
they take the config's ``num_steps``; if they disagree among themselves, a
:class:`NumStepsError` lists them, since which of them was meant cannot be
told.
"""
from typing import Any, Dict, List, Tuple

from ..core.arguments import NUM_STEPS, excerpt

__all__ = ['NumStepsError', 'apply_num_steps', 'RUNTIME_KEYS']

#: the parts of a config that the runner builds
RUNTIME_KEYS = ('model', 'train_dataloader', 'val_dataloader',
                'test_dataloader')


class NumStepsError(ValueError):
    """The T fields of a config cannot be made to agree with ``num_steps``."""


def _num_steps_fields(node: Any, path: str,
                      found: List[Tuple[str, Any, Any]]) -> None:
    """Append ``(path, container, key)`` of every ``num_steps`` in ``node``."""
    if isinstance(node, dict):
        for key, value in node.items():
            where = f'{path}.{key}'
            if key == 'num_steps':
                found.append((where, node, key))
            else:
                _num_steps_fields(value, where, found)
    elif isinstance(node, (list, tuple)):
        for index, value in enumerate(node):
            _num_steps_fields(value, f'{path}[{index}]', found)


def _t_fields(cfg) -> List[Tuple[str, Any, Any]]:
    found: List[Tuple[str, Any, Any]] = []
    for key in RUNTIME_KEYS:
        if cfg.get(key) is not None:
            _num_steps_fields(cfg[key], key, found)
    model = cfg.get('model') or {}
    backbone = model.get('backbone') or {}
    if 'num_steps' in (model.get('data_preprocessor') or {}) and \
            'in_channels' in backbone:
        found.append(('model.backbone.in_channels', backbone, 'in_channels'))
    return found


def apply_num_steps(cfg) -> Dict[str, int]:
    """Give every T field of ``cfg`` (an mmengine ``Config``) the value of
    its top-level ``num_steps``, in place.

    Returns:
        ``{field path: old value}`` of the fields that changed (empty when
        the config has no ``num_steps`` or already agrees).

    Raises:
        NumStepsError: ``num_steps`` is not a positive integer, or the T
            fields disagree among themselves and with it.
    """
    target = cfg.get('num_steps')
    if target is None:
        return {}
    if not NUM_STEPS.accepts(target):
        raise NumStepsError(
            f'num_steps (T, spike frames per sample) must be '
            f'{NUM_STEPS.describe()}, got {excerpt(target)}')
    fields = _t_fields(cfg)
    values = {path: container[key] for path, container, key in fields}
    stale = {path: value for path, value in values.items()
             if value != target}
    if not stale:
        return {}
    if len(set(values.values())) > 1:
        listing = '\n'.join(f'  {path} = {value!r}'
                            for path, value in values.items())
        raise NumStepsError(
            f'num_steps = {target}, but the fields built from T disagree:\n'
            f'{listing}\nSet T once: `--cfg-options num_steps={target}` '
            f'(tools/train.py, tools/test.py), WGSE_NUM_STEPS={target} in '
            f'the environment (any mmengine tool), or num_steps = {target} '
            f'alone in a config that inherits a shipped one; or make these '
            f'fields agree.')
    for path, container, key in fields:
        container[key] = target
    return stale
