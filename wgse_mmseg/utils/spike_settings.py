"""The spike settings a config sets once, and the fields that carry them.

A spike config sets ``num_steps`` (T), ``data_root`` and ``crop_size`` once,
as plain top-level values (the dataset base configs), and its fields take
them from there when it is parsed: ``{{_base_.num_steps}}`` or a plain
variable. A change made after parsing (``--cfg-options num_steps=41``) or in
a child config (``num_steps = 41`` in a config that inherits a shipped one)
reaches the setting but not the fields already computed from it.
:func:`apply_spike_settings` closes that gap, the one mechanism for the
three settings: it gives each setting's value to the fields listed for it in
:data:`SPIKE_SETTINGS`, and to no other field. The project's config loader
(:func:`wgse_mmseg.utils.config.load_config`) and the configs' runner
(:class:`~wgse_mmseg.engine.SpikeRunner`, so MMSeg's own ``tools/train.py``
and ``mim train`` too) call it.

Which fields take a setting's value:

* the listed fields that hold one value, different from the setting's: the
  config changed the setting after its base derived them, so all take it;
* ``num_steps``: its fields must all hold T (the loader's window, the
  preprocessor's check, ...); fields that disagree among themselves raise
  :class:`SpikeSettingsError` listing them, since which of them was meant
  cannot be told;
* the stem of a spike model (one whose data preprocessor has
  ``num_steps``) takes T channels, whatever the backbone: every enhancer
  keeps T channels, so there is no other width it could take. The
  ``in_channels`` of the backbone and of each backbone nested in its config
  (``backbone_cfg``: BiSeNetV1's, ICNet's, STDC's context path) becomes T,
  also where it holds an RGB base's 3; where the config does not set it
  and the registered class takes ``in_channels`` (at any depth of its
  constructors), it is added (:func:`stem_fields`). A backbone that takes
  no ``in_channels`` (MobileNetV2/V3) is left as it is: the start-up check
  (:mod:`wgse_mmseg.utils.cross_checks`) names its first layer;
* ``data_root`` and ``crop_size``: a field that holds another value than
  the setting while others hold the setting was set apart on purpose (a
  separate training root, a validation crop) and keeps its value.

A command-line value (``overrides``) goes to the fields that hold the
setting's value as the config gives it, then becomes the setting's value.
"""
import inspect
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

from ..command_line import FRAME_SIZE, NUM_STEPS, SIDE, Argument, OneOf, Path
from ..errors import WgseError, excerpt

__all__ = []


class SpikeSettingsError(WgseError, ValueError):
    """A spike setting is not valid, or its fields cannot be made to agree
    with it."""


@dataclass(frozen=True)
class _SpikeSetting:
    """A top-level config value and the fields that carry it.

    Attributes:
        name: the top-level key (``num_steps``).
        kind: what the value must be.
        fields: dotted paths from the config's root. A part ``pipeline[A|B]``
            stands for every step of type ``A`` or ``B`` in that pipeline;
            a path missing from a config is skipped.
        agree: every field must hold the value (else a field may be set
            apart).
        hint: the value's form on the command line.
    """
    name: str
    kind: Argument
    fields: Tuple[str, ...]
    agree: bool = False
    hint: str = ''


def _loaders(*suffixes: str) -> Tuple[str, ...]:
    """``suffix`` under the dataset of each of the three data loaders."""
    return tuple(f'{split}_dataloader.dataset.{suffix}'
                 for split in ('train', 'val', 'test') for suffix in suffixes)


#: the steps of a pipeline that read or simulate T frames
_T_STEPS = 'pipeline[LoadSpikeFromFile|LoadSpikeImagePair|SimulateSpikes]'

#: The settings and the fields that carry them; nothing else is changed.
#: ``train_pipeline`` and ``test_pipeline`` are MMSeg's top-level copies
#: (``mmseg.apis.inference_model`` reads ``test_pipeline``).
SPIKE_SETTINGS = (
    _SpikeSetting(
        'num_steps', NUM_STEPS, agree=True, hint='T',
        fields=('model.data_preprocessor.num_steps',
                'model.num_steps',  # SpikeReconstructor
                *_loaders('num_steps',  # SimulatedSpikeImageDataset
                          f'{_T_STEPS}.num_steps'),
                f'train_{_T_STEPS}.num_steps', f'test_{_T_STEPS}.num_steps',
                f'tta_{_T_STEPS}.num_steps')),
    _SpikeSetting('data_root', Path(), hint='DIR',
                  fields=_loaders('data_root')),
    _SpikeSetting(
        'crop_size', OneOf(SIDE, FRAME_SIZE), hint='H,W',
        fields=('model.data_preprocessor.size',  # pads training batches
                'train_dataloader.dataset.crop_size',  # simulated images
                'train_dataloader.dataset.pipeline[SpikeRandomCrop].'
                'crop_size',
                'train_pipeline[SpikeRandomCrop].crop_size')),
)
_BY_NAME = {setting.name: setting for setting in SPIKE_SETTINGS}


def _same(value: Any) -> Any:
    """``value`` with lists as tuples, so that (H, W) compares as read."""
    return tuple(value) if isinstance(value, (list, tuple)) else value


def check_setting(name: str, value: Any, text: bool = False) -> Any:
    """The checked value of setting ``name``, lists as tuples.

    With ``text`` (a command-line value) a string is converted first
    (``'41'``, ``'128,256'``); ``crop_size`` also takes one side for a
    square, as ``--cfg-options`` always has. Raises
    :class:`SpikeSettingsError` naming the setting.
    """
    setting = _BY_NAME[name]
    if text and isinstance(value, str):
        try:
            converted = setting.kind.convert(value)
        except (TypeError, ValueError, OverflowError):
            converted = None
        value = value if converted is None else converted
    value = _same(value)
    if not setting.kind.accepts(value):
        raise SpikeSettingsError(
            f'{name} must be {setting.kind.describe()} (`--cfg-options '
            f'{name}={setting.hint}`), got {excerpt(value)}')
    if name == 'crop_size' and SIDE.accepts(value):  # one side: a square
        value = (value, value)
    return value


def _resolve(node: Any, parts: List[str], path: str,
             found: List[Tuple[str, Any, str]]) -> None:
    """Append ``(path, container, key)`` for ``parts`` under ``node``."""
    if not isinstance(node, dict):
        return
    head, rest = parts[0], parts[1:]
    if '[' in head:
        key, types = head[:-1].split('[')
        steps = node.get(key)
        if not isinstance(steps, (list, tuple)):
            return
        for index, step in enumerate(steps):
            if isinstance(step, dict) and step.get('type') in \
                    types.split('|'):
                _resolve(step, rest, f'{path}{key}[{index}].', found)
    elif not rest:
        if head in node:
            found.append((path + head, node, head))
    else:
        _resolve(node.get(head), rest, f'{path}{head}.', found)


def _find(cfg, spec: str) -> List[Tuple[str, Any, str]]:
    """``(path, container, key)`` of every field ``spec`` names in ``cfg``."""
    found: List[Tuple[str, Any, str]] = []
    root = spec.split('.')[0].split('[')[0]
    # a Config is no dict: start from a dict of the top-level entry (the
    # same object, so the fields found are the config's own)
    _resolve({root: cfg.get(root)}, spec.split('.'), '', found)
    return found


def _fields(cfg, setting: _SpikeSetting) -> List[Tuple[str, Any, str]]:
    """``(path, container, key)`` of the fields of ``setting`` in ``cfg``."""
    found: List[Tuple[str, Any, str]] = []
    for spec in setting.fields:
        found.extend(_find(cfg, spec))
    return found


#: keys of a backbone's config that hold a backbone of its own, which
#: sees the model's input too
INNER_BACKBONE_KEYS = ('backbone_cfg',)


def takes_in_channels(kind: Any) -> bool:
    """Whether the backbone ``kind`` (a config's ``type``: a registered
    name or a class) takes ``in_channels``, by its constructors' signatures
    (following ``**kwargs`` to the base classes). A name is looked up in
    MMSeg's registry only where it is a plain identifier (a dotted name
    would make mmengine import a module); ``False`` where it cannot be
    found."""
    if isinstance(kind, str):
        if not kind.isidentifier():
            return False
        try:
            from mmseg.registry import MODELS
            kind = MODELS.get(kind)
        except Exception:  # no MMSeg, or a registry that cannot look it up
            return False
    if not inspect.isclass(kind):
        return False
    for klass in kind.__mro__:
        init = klass.__dict__.get('__init__')
        if init is None:
            continue
        try:
            parameters = inspect.signature(init).parameters
        except (TypeError, ValueError):
            return False
        if 'in_channels' in parameters:
            return True
        if not any(p.kind is p.VAR_KEYWORD for p in parameters.values()):
            return False
    return False


def stem_fields(cfg) -> List[Tuple[str, dict]]:
    """``(path, backbone config)`` of every backbone of ``cfg``'s model
    that sees its input: ``model.backbone`` and the backbones nested in it
    (:data:`INNER_BACKBONE_KEYS`), for a spike model only (a data
    preprocessor with ``num_steps``); their ``in_channels`` is the stem's
    width."""
    model = cfg.get('model')
    if not isinstance(model, dict) or not isinstance(
            model.get('data_preprocessor'), dict) or \
            'num_steps' not in model['data_preprocessor']:
        return []
    found: List[Tuple[str, dict]] = []
    pending = [('model.backbone', model.get('backbone'))]
    while pending:
        path, backbone = pending.pop(0)
        if not isinstance(backbone, dict):
            continue
        found.append((path, backbone))
        pending.extend((f'{path}.{key}', backbone.get(key))
                       for key in INNER_BACKBONE_KEYS)
    return found


def _give_stems(cfg, num_steps: int) -> Dict[str, Any]:
    """T to every stem's ``in_channels`` (module docstring); returns
    ``{path: old value}`` of those that changed (``None``: added)."""
    changed: Dict[str, Any] = {}
    for path, backbone in stem_fields(cfg):
        present = 'in_channels' in backbone
        if present and backbone['in_channels'] == num_steps:
            continue
        if present or takes_in_channels(backbone.get('type')):
            changed[f'{path}.in_channels'] = backbone.get('in_channels')
            backbone['in_channels'] = num_steps
    return changed


def _reconcile(cfg, setting: _SpikeSetting) -> Dict[str, Any]:
    """Give ``cfg[setting.name]`` to its fields (module docstring)."""
    target = check_setting(setting.name, cfg[setting.name])
    fields = _fields(cfg, setting)
    values = {path: _same(container[key]) for path, container, key in fields}
    stale = {path: value for path, value in values.items()
             if value != target}
    if not stale:
        return {}
    if len(set(values.values())) > 1:
        if not setting.agree and len(stale) < len(values):
            return {}  # set apart on purpose
        listing = '\n'.join(f'  {path} = {value!r}'
                            for path, value in values.items())
        shown = ','.join(map(str, target)) if isinstance(
            target, tuple) else target
        raise SpikeSettingsError(
            f'{setting.name} = {target!r}, but the fields built from it '
            f'disagree:\n{listing}\nSet {setting.name} once: '
            f'`--cfg-options {setting.name}={shown}` (tools/train.py, '
            f'tools/test.py, and MMSeg\'s tools with the configs\' runner), '
            f'or {setting.name} = {target!r} alone in a config that inherits '
            f'a shipped one; or make these fields agree.')
    for path, container, key in fields:
        container[key] = target
    return stale


def apply_spike_settings(cfg, overrides: Optional[Dict[str, Any]] = None
                         ) -> Dict[str, Any]:
    """Give each spike setting of ``cfg`` (an mmengine ``Config``) to the
    fields that carry it, in place; then each of ``overrides`` (command-line
    values, checked) to the fields that hold the config's value.

    Returns:
        ``{field path: old value}`` of the fields that changed.

    Raises:
        SpikeSettingsError: a value is not valid, or the fields of a setting
            disagree among themselves and with it.
    """
    changed: Dict[str, Any] = {}
    for setting in SPIKE_SETTINGS:
        if cfg.get(setting.name) is not None:
            changed.update(_reconcile(cfg, setting))
    for name, value in (overrides or {}).items():
        value = check_setting(name, value, text=True)
        current = cfg.get(name)
        if current is not None:
            current = _same(current)
            for path, container, key in _fields(cfg, _BY_NAME[name]):
                if _same(container[key]) == current and value != current:
                    changed.setdefault(path, container[key])
                    container[key] = value
        cfg[name] = value
    num_steps = cfg.get('num_steps')
    if num_steps is None:  # a config without the setting: its model's T
        model = cfg.get('model')
        preprocessor = model.get('data_preprocessor') if isinstance(
            model, dict) else None
        num_steps = preprocessor.get('num_steps') if isinstance(
            preprocessor, dict) else None
    if isinstance(num_steps, int) and not isinstance(num_steps, bool):
        for path, old in _give_stems(cfg, num_steps).items():
            changed.setdefault(path, old)
    return changed
