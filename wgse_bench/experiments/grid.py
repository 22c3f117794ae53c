"""Experiment grids: their entries and the ``--cfg-options`` of a run.

A grid (e.g. ``configs/experiments/grid_cpu.py``) lists models and
enhancers; each entry ``<model>_<enhancer>`` is the model's config with
``model.data_preprocessor.enhancer`` overridden (:func:`load_grid`). This
module turns an entry and a schedule into ``--cfg-options`` words for the
train and test tools (:func:`enhancer_options`, :func:`schedule_options`,
:func:`as_cli`).
"""
import fnmatch
import os
import os.path as osp
from typing import Any, Dict, List, NamedTuple, Optional, Sequence, Tuple

from mmengine.config import Config

import wgse_mmseg
from wgse_mmseg.argument_checks import ArgumentError, check_path
from wgse_mmseg.errors import excerpt
from wgse_mmseg.utils.config import parse_option_value

from .settings import check_schedule

_PACKAGE = osp.dirname(osp.abspath(wgse_mmseg.__file__))
#: where the package keeps its ``configs/`` and ``tools/``: ``wgse_mmseg/.mim``
#: (MMSeg's convention for mim; ``setup.py`` copies or links them there), or
#: the checkout itself for a PEP 660 editable install, which has no ``.mim``
PROJECT_ROOT = (osp.join(_PACKAGE, '.mim')
                if osp.isdir(osp.join(_PACKAGE, '.mim', 'configs'))
                else osp.dirname(_PACKAGE))
ENHANCER_KEY = 'model.data_preprocessor.enhancer'


class Entry(NamedTuple):
    """One grid entry: a model config with one enhancer in front.

    Further ``--cfg-options`` for training, testing and the benchmark:
    ``model_options``, the model's (e.g. a shallower backbone), then
    ``variant_options``, the enhancer variant's (e.g. its learning rate).
    """
    name: str
    model: str
    config: str
    enhancer_name: str
    enhancer: Optional[dict]
    model_options: Dict[str, Any]
    variant_options: Dict[str, Any]


def _split(path: str, what: str, value: Any, main: str,
           is_main: bool) -> Tuple[Any, Dict[str, Any]]:
    """``(main value, cfg_options)`` of a grid value given either alone or
    as ``dict(<main>=..., cfg_options=dict(...))``."""
    if not (isinstance(value, dict) and not is_main):
        return value, {}
    unknown = set(value) - {main, 'cfg_options'}
    if main not in value or unknown:
        raise ValueError(f'{path}: {what} must be given alone or as '
                         f'dict({main}=..., cfg_options=dict(...)), got '
                         f'{dict(value)!r}')
    options = dict(value.get('cfg_options') or {})
    as_cli(options)  # a clear error now for what the command line can't carry
    return value[main], options


def load_grid(path: str) -> Tuple[Config, List[Entry]]:
    """The grid config and its entries, models outer, enhancers inner.

    A model is a config path, relative to the project root, where
    ``configs/`` is (or absolute), or ``dict(config=PATH,
    cfg_options=dict(...))``. An enhancer is ``None`` (raw spikes), an
    enhancer config (``dict(type=...)``) or ``dict(enhancer=None | dict(
    type=...), cfg_options=dict(...))``: a variant that also changes the
    training recipe.
    """
    check_path('load_grid', 'path', path, exists='file')
    if not os.fspath(path).endswith('.py'):
        raise ArgumentError('load_grid', 'path', 'a grid file (.py)', path)
    grid = Config.fromfile(path)
    for key in ('models', 'enhancers', 'cfg_options', 'epochs', 'seeds',
                'latency'):
        if key not in grid:
            raise ValueError(f'{path}: the grid must define {key!r}')
    for key, kinds in (('models', 'a config path or dict(config=..., '
                                  'cfg_options=...)'),
                       ('enhancers', 'None, an enhancer dict(type=...) or '
                                     'dict(enhancer=..., cfg_options=...)')):
        if not isinstance(grid[key], dict) or not grid[key]:
            raise ValueError(
                f'{path}: {key} must be a dict of names to {kinds}, got '
                f'{excerpt(grid[key])}')
        for name, value in grid[key].items():
            if not (value is None and key == 'enhancers' or
                    isinstance(value, dict) or
                    isinstance(value, str) and key == 'models'):
                raise ValueError(f'{path}: {key}[{name!r}] must be {kinds}, '
                                 f'got {excerpt(value)}')
    entries = []
    for model, value in grid.models.items():
        config, model_options = _split(path, f'model {model!r}', value,
                                       'config', isinstance(value, str))
        if not isinstance(config, str):
            raise ValueError(f'{path}: model {model!r}: config must be a '
                             f'path, got {excerpt(config)}')
        config = osp.join(PROJECT_ROOT, config)
        if not osp.isfile(config):
            raise FileNotFoundError(f'{path}: model {model!r}: {config} '
                                    f'does not exist')
        for name, value in grid.enhancers.items():
            enhancer, options = _split(
                path, f'enhancer {name!r}', value, 'enhancer',
                value is None or 'type' in value)
            if not (enhancer is None or isinstance(enhancer, dict)):
                raise ValueError(f'{path}: enhancer {name!r} must be None '
                                 f'or dict(type=...), got '
                                 f'{excerpt(enhancer)}')
            entries.append(Entry(f'{model}_{name}', model, config, name,
                                 None if enhancer is None else
                                 dict(enhancer), model_options, options))
    return grid, entries


def select(entries: List[Entry],
           patterns: Optional[Sequence[str]]) -> List[Entry]:
    """Entries matching any of the shell-style ``patterns`` (all if none);
    a pattern matching nothing is an error that lists the names."""
    if not patterns:
        return entries
    for pattern in patterns:
        if not any(fnmatch.fnmatchcase(e.name, pattern) for e in entries):
            raise ValueError(f'--only {pattern!r} matches no entry; the '
                             f'grid has: {", ".join(e.name for e in entries)}')
    return [e for e in entries
            if any(fnmatch.fnmatchcase(e.name, p) for p in patterns)]


def enhancer_options(enhancer: Optional[dict]) -> Dict[str, Any]:
    """``--cfg-options`` replacing the enhancer of a raw-spike config."""
    if enhancer is None:
        return {ENHANCER_KEY: None}
    options = {f'{ENHANCER_KEY}._delete_': True}
    options.update({f'{ENHANCER_KEY}.{k}': v for k, v in enhancer.items()})
    return options


def schedule_options(epochs: Optional[int],
                     max_iters: Optional[int]) -> Tuple[Dict[str, Any], str]:
    """``--cfg-options`` for the schedule and the final checkpoint's name.

    The base schedule's shape is kept: linear warm-up for a tenth of the
    run (at least one epoch or iteration), then polynomial decay to the end
    (a one-epoch run is warm-up only). A checkpoint is kept after every epoch
    (a tenth of the iterations), so an interrupted run resumes; validation
    during training is off (the run is tested afterwards).
    """
    length = check_schedule('schedule_options', epochs, max_iters)
    warmup = max(1, length // 10)
    options = {
        'val_cfg': None, 'val_dataloader': None, 'val_evaluator': None,
        'param_scheduler.0.end': warmup,
        'param_scheduler.1.begin': warmup,
        'param_scheduler.1.end': max(length, warmup + 1),
        'default_hooks.checkpoint.max_keep_ckpts': 1,
    }
    if max_iters is None:
        options.update({'train_cfg.max_epochs': epochs,
                        'default_hooks.checkpoint.interval': 1})
        return options, f'epoch_{epochs}.pth'
    for index in (0, 1):
        options.update({f'param_scheduler.{index}.by_epoch': False,
                        f'param_scheduler.{index}.convert_to_iter_based':
                        False})
    options.update({
        'train_cfg._delete_': True,
        'train_cfg.type': 'IterBasedTrainLoop',
        'train_cfg.max_iters': max_iters,
        'default_hooks.checkpoint.by_epoch': False,
        'default_hooks.checkpoint.interval': warmup,
        'default_hooks.logger.log_metric_by_epoch': False,
        'log_processor.by_epoch': False,
    })
    return options, f'iter_{max_iters}.pth'


def as_cli(options: Dict[str, Any]) -> List[str]:
    """``key=value`` words that ``--cfg-options`` parses back to ``options``
    (strings, ints, floats, booleans and ``None``;
    :func:`~wgse_mmseg.utils.config.parse_option_value`; a string may
    spell a number or a list, ``'32,64'``); a string that would come back
    as another string, a boolean or ``None``, or not at all, is refused."""
    words = []
    for key, value in options.items():
        if not isinstance(value, (str, int, float, bool, type(None))):
            raise TypeError(f'{key}={value!r}: only str, int, float, bool '
                            f'and None can be passed as --cfg-options')
        if isinstance(value, str):
            try:
                back = parse_option_value(value)
            except ValueError:
                back = None
            if not value or back is None or isinstance(back, bool) or (
                    isinstance(back, str) and back != value):
                raise ValueError(f'{key}={value!r} would not survive the '
                                 f'command line as a string')
        words.append(f'{key}={value}')
    return words


def describe(enhancer: Optional[dict],
             variant_options: Optional[Dict[str, Any]] = None) -> str:
    """``TFP(window=21)``; ``none`` for raw spikes; a variant's options
    follow, e.g. ``WGSE(dim=1); ...custom_keys.enhancer.lr_mult=10``."""
    if enhancer is None:
        text = 'none'
    else:
        args = ', '.join(f'{k}={v}' for k, v in enhancer.items()
                         if k != 'type')
        text = f"{enhancer['type']}({args})"
    return '; '.join([text] + [f'{k}={v}' for k, v in
                               (variant_options or {}).items()])
