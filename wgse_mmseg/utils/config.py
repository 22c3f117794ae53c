"""Loading configs with the spike settings overridable from the command line.

The dataset base configs set ``num_steps`` (T), ``data_root`` and
``crop_size`` once; :func:`load_config` gives the values of
``--cfg-options num_steps=41 data_root=DIR crop_size=128,256`` (and those a
child config sets) to every field that carries them
(:func:`~wgse_mmseg.utils.spike_settings.apply_spike_settings`, which lists
them), and merges the other keys as mmengine does.

The tools' arguments (:func:`add_runner_arguments`, :func:`add_config_options`)
are built without importing mmengine or torch, so that a tool answers
``--help`` at once; mmengine is imported where a config is read.
"""
import argparse
import os
import os.path as osp
import re
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Union

from ..command_line import Choice, Integer, Path
from ..errors import excerpt
from ..fileio.input_guard import note_input
from ..limits import MAX_WORKERS
from ..openmmlab_stack import prepare_mmseg_layer
from .spike_settings import (SPIKE_SETTINGS, SpikeSettingsError,
                             apply_spike_settings, check_setting)

if TYPE_CHECKING:
    from mmengine.config import Config
    from mmengine.runner import Runner

__all__ = []

#: the file types mmengine reads a config from
CONFIG_EXTENSIONS = ('.py', '.json', '.yaml', '.yml')
#: ``--cfg-options`` key -> the declaration of its value (from
#: :data:`~wgse_mmseg.utils.spike_settings.SPIKE_SETTINGS`)
SPIKE_SETTING_KINDS = {setting.name: setting.kind
                       for setting in SPIKE_SETTINGS}


def load_config(path: Union[str, 'Config'],
                cfg_options: Optional[Dict] = None) -> 'Config':
    """``Config.fromfile(path)`` (or the ``Config`` ``path`` itself) with
    ``cfg_options`` applied.

    ``num_steps``, ``data_root`` and ``crop_size`` in ``cfg_options`` go to
    the fields that carry them, before the other keys are merged with
    ``Config.merge_from_dict`` (so ``val_dataloader.dataset.data_root=A``
    beside ``data_root=B`` keeps ``A``); then the fields are checked against
    the settings once more (see :mod:`wgse_mmseg.utils.spike_settings`).
    Sets the MMSeg layer up first (:func:`~wgse_mmseg.openmmlab_stack.
    prepare_mmseg_layer`), which the configs' ``mmseg::`` bases need on the
    onedl stack.
    """
    prepare_mmseg_layer('load_config')
    from mmengine.config import Config
    if not isinstance(path, Config):
        if not osp.isfile(path):
            raise FileNotFoundError(f'{path}: no such config file')
        if osp.splitext(path)[1] not in CONFIG_EXTENSIONS:
            raise ValueError(f'{path}: not a config file (expected one of '
                             f'{", ".join(CONFIG_EXTENSIONS)})')
        note_input(path)
    options = dict(cfg_options or {})
    settings = {setting.name: options.pop(setting.name)
                for setting in SPIKE_SETTINGS if setting.name in options}
    cfg = path if isinstance(path, Config) else Config.fromfile(path)
    apply_spike_settings(cfg, settings)
    if options:
        cfg.merge_from_dict(options)
        apply_spike_settings(cfg)
    return cfg


#: brackets nested deeper than this in a ``--cfg-options`` value are refused
MAX_OPTION_DEPTH = 32
_CLOSING = {'[': ']', '(': ')'}
_QUOTES = '\'"'


def _top_level_commas(text: str) -> List[int]:
    """Where ``text`` has a comma outside brackets (quotes do not protect
    one, as in ``DictAction``); raises ``ValueError`` for unbalanced
    brackets or nesting deeper than :data:`MAX_OPTION_DEPTH`."""
    stack, commas = [], []
    for index, char in enumerate(text):
        if char in _CLOSING:
            stack.append(_CLOSING[char])
            if len(stack) > MAX_OPTION_DEPTH:
                raise ValueError(f'brackets nested deeper than '
                                 f'{MAX_OPTION_DEPTH} levels')
        elif char in ')]':
            if not stack or stack.pop() != char:
                raise ValueError('unbalanced brackets')
        elif char == ',' and not stack:
            commas.append(index)
    if stack:
        raise ValueError('unbalanced brackets')
    return commas


def _unquoted(text: str) -> str:
    """``text`` without the spaces around it and the matching quotes
    around that (repeatedly: ``"'3'"`` is ``3``); a quote left at either
    end (``'abc``, ``"a,b",c`` split at its comma) is refused, where
    ``DictAction`` would drop it."""
    text = text.strip()
    while len(text) >= 2 and text[0] == text[-1] and text[0] in _QUOTES:
        text = text[1:-1].strip()
    if text and (text[0] in _QUOTES or text[-1] in _QUOTES):
        raise ValueError(f'unmatched quote in {excerpt(text)} (quotes do '
                         f'not protect a comma)')
    return text


def _scalar(text: str) -> Any:
    """One value as ``DictAction._parse_int_float_bool`` reads it (an
    ``int``, a ``float``, ``True``/``False`` in any case, ``None``, else
    the text), except that the spaces inside a string are kept; a text
    that reads otherwise without its spaces (``1 000``, ``Tr ue``) is
    refused as ambiguous."""
    def read(word: str) -> Any:
        for kind in (int, float):
            try:
                return kind(word)
            except ValueError:
                pass
        if word.lower() in ('true', 'false'):
            return word.lower() == 'true'
        return None if word == 'None' else word

    value, squeezed = read(text), re.sub(r'\s', '', text)
    if isinstance(value, str) and not isinstance(read(squeezed), str):
        raise ValueError(f'{excerpt(text)} is ambiguous: a string as typed, '
                         f'{read(squeezed)!r} without its spaces')
    return value


def parse_option_value(text: str) -> Any:
    """A ``--cfg-options`` value as mmengine's ``DictAction`` reads it,
    except for spaces: ``DictAction`` drops every space, so
    ``data_root=D/my data`` would read ``D/mydata``; here only the
    spaces around a value or an item go.

    As in ``DictAction``: the quotes around a value or item are dropped
    and what they hold is read (``"[1,2]"`` is ``[1, 2]``, ``'3'`` is
    ``3``, ``'None'`` is ``None``); ``[a, b]`` is a list, ``(a, b)`` a
    tuple, ``a,b`` a list (a trailing comma ends it), nested to any depth
    up to :data:`MAX_OPTION_DEPTH`; a single value is an ``int``,
    ``float``, ``bool`` (any case), ``None`` or the string itself.

    Raises:
        ValueError: unbalanced brackets, an unmatched quote, nesting
            deeper than :data:`MAX_OPTION_DEPTH`, or a string whose spaces
            hide a number, a bool or ``None`` (``1 000``).
    """
    text = _unquoted(text)
    commas = _top_level_commas(text)
    if not commas and text[:1] in _CLOSING and \
            text[-1:] == _CLOSING[text[0]]:
        items = _items(text[1:-1])
        return tuple(items) if text[0] == '(' else items
    if commas:
        return _items(text)
    return _scalar(text)


def _items(text: str) -> List[Any]:
    """The comma-separated items of ``text`` (none in a blank text; a
    trailing comma ends the list), each read by
    :func:`parse_option_value`."""
    if not text.strip():
        return []
    bounds = [-1] + _top_level_commas(text) + [len(text)]
    parts = [text[a + 1:b] for a, b in zip(bounds, bounds[1:])]
    if len(parts) > 1 and not parts[-1].strip():
        parts.pop()
    return [parse_option_value(part) for part in parts]


class ConfigOptions(argparse.Action):
    """``--cfg-options key=value ...``, read as mmengine's ``DictAction`` reads
    them (lists, tuples, numbers) but with every
    value read exactly as typed (:func:`parse_option_value`; a word it
    cannot read is refused naming it), and the spike settings checked
    against :data:`SPIKE_SETTING_KINDS` as the command line is parsed, so
    argparse exits with ``argument --cfg-options: num_steps must be
    ...``."""

    def __call__(self, parser, namespace, values, option_string=None):
        options = dict(getattr(namespace, self.dest, None) or {})
        for word in values or ():
            key, equals, value = word.partition('=')
            if not key or not equals:
                raise argparse.ArgumentError(
                    self, f'must be key=value words, got {excerpt(word)}')
            try:
                options[key] = parse_option_value(value)
            except ValueError as err:
                raise argparse.ArgumentError(
                    self, f'{key}: {err} in {excerpt(value)}') from None
        for key in SPIKE_SETTING_KINDS.keys() & options.keys():
            try:  # kept as checked: '41' (quoted) is T=41
                options[key] = check_setting(key, options[key], text=True)
            except SpikeSettingsError as err:
                raise argparse.ArgumentError(self, str(err)) from None
        setattr(namespace, self.dest, options)


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """A tool's ``--cfg-options`` (:class:`ConfigOptions`), for
    :func:`load_config`."""
    parser.add_argument(
        '--cfg-options', nargs='+', action=ConfigOptions, default={},
        help='override config settings, key=value; num_steps, data_root and '
        'crop_size reach every field that carries them')


def add_runner_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments shared by the train and test tools (as in MMSeg's tools)."""
    parser.add_argument('--work-dir', type=Path(),
                        help='the dir to save logs and models')
    add_config_options(parser)
    parser.add_argument('--launcher',
                        type=Choice(['none', 'pytorch', 'slurm', 'mpi']),
                        default='none', help='job launcher')
    parser.add_argument('--local_rank', '--local-rank',
                        type=Integer(0, MAX_WORKERS - 1), default=0)


def config_from_args(args: argparse.Namespace) -> 'Config':
    """The config of ``args.config`` set up for an mmengine ``Runner``.

    Applies ``--cfg-options``, the launcher and the work dir (default
    ``./work_dirs/<config name>``), and sets ``LOCAL_RANK`` if unset;
    distributed runs on a machine without CUDA use gloo
    (:func:`~wgse_mmseg.utils.distributed.prepare_launcher`).
    """
    from .distributed import prepare_launcher
    os.environ.setdefault('LOCAL_RANK', str(args.local_rank))
    cfg = load_config(args.config, args.cfg_options)
    cfg.launcher = args.launcher
    if args.work_dir is not None:
        cfg.work_dir = args.work_dir
    elif cfg.get('work_dir', None) is None:
        cfg.work_dir = osp.join('./work_dirs',
                                osp.splitext(osp.basename(args.config))[0])
    prepare_launcher(cfg)
    return cfg


def build_runner(cfg: 'Config') -> 'Runner':
    """The runner of ``cfg``, as MMSeg's tools build it: the config's
    ``runner_type`` (the shipped configs': ``SpikeRunner``) where it names
    one, else mmengine's ``Runner``."""
    from mmengine.registry import RUNNERS
    from mmengine.runner import Runner
    if 'runner_type' in cfg:
        return RUNNERS.build(cfg)
    return Runner.from_cfg(cfg)
