"""Loading configs with the spike settings overridable from the command line.

The dataset base config sets ``num_steps`` (T), ``data_root`` and
``crop_size`` once, through mmengine's ``{{$ENV:default}}`` substitution, and
every field that depends on them (the loader's window, the preprocessor's
check and padding, the backbone's ``in_channels``) is derived from them when
the file is parsed. ``--cfg-options num_steps=41`` can therefore not be a
plain merge after parsing: :func:`load_config` turns these keys into the
environment variables the config reads, then merges the rest as usual.
"""
import argparse
import os
import os.path as osp
from numbers import Integral
from typing import Dict, Optional

from mmengine.config import Config, DictAction
from mmengine.registry import RUNNERS
from mmengine.runner import Runner

from ..core.arguments import (FRAME_SIZE, NUM_STEPS, SIDE, ArgumentError,
                              Choice, Integer, OneOf, Path)
from ..core.limits import MAX_WORKERS, excerpt
from .distributed import prepare_launcher
from .num_steps import apply_num_steps

__all__ = [
    'SPIKE_SETTINGS', 'SPIKE_SETTING_KINDS', 'ConfigOptions', 'load_config',
    'add_config_options', 'add_runner_arguments', 'config_from_args',
    'build_runner'
]

#: ``--cfg-options`` key -> environment variable read by the config files.
SPIKE_SETTINGS = {
    'num_steps': 'WGSE_NUM_STEPS',
    'data_root': 'WGSE_DATA_ROOT',
    'crop_size': 'WGSE_CROP_SIZE',
}


#: ``--cfg-options`` key -> the declaration of its value: ``crop_size`` is
#: one side (a square) or ``H,W``
SPIKE_SETTING_KINDS = {
    'num_steps': NUM_STEPS,
    'data_root': Path(),
    'crop_size': OneOf(SIDE, FRAME_SIZE),
}


def _as_env_value(key: str, value) -> str:
    """The text of spike setting ``key``'s environment variable, its value
    checked against :data:`SPIKE_SETTING_KINDS` (a string is read as a
    command-line word: ``'41'``, ``'128,256'``).

    Raises:
        ArgumentError: naming ``key``, for a value its declaration refuses.
    """
    value = SPIKE_SETTING_KINDS[key].parse(value, 'load_config', key)
    if key == 'crop_size':
        sizes = (value, value) if isinstance(value, Integral) else value
        return ','.join(str(int(v)) for v in sizes)
    return str(int(value)) if key == 'num_steps' else os.fspath(value)


def load_config(path: str, cfg_options: Optional[Dict] = None) -> Config:
    """``Config.fromfile(path)`` with ``cfg_options`` applied.

    ``num_steps``, ``data_root`` and ``crop_size`` in ``cfg_options`` are
    applied before parsing (see module docstring); other keys are merged
    with ``Config.merge_from_dict``. Then the config's ``num_steps`` reaches
    every field built from it, also where a child config set it
    (:func:`~wgse_mmseg.utils.num_steps.apply_num_steps`).
    """
    options = dict(cfg_options or {})
    saved = {}
    for key, env in SPIKE_SETTINGS.items():
        if key in options:
            saved[env] = os.environ.get(env)
            os.environ[env] = _as_env_value(key, options.pop(key))
    try:
        cfg = Config.fromfile(path)
    finally:
        for env, value in saved.items():
            if value is None:
                os.environ.pop(env, None)
            else:
                os.environ[env] = value
    if options:
        cfg.merge_from_dict(options)
    apply_num_steps(cfg)
    return cfg


class ConfigOptions(DictAction):
    """mmengine's ``DictAction`` (``key=value`` words, values read as
    Python literals), refusing a word it cannot read and checking the spike
    settings against :data:`SPIKE_SETTING_KINDS` as the command line is
    parsed, so argparse exits with ``argument --cfg-options: num_steps must
    be ...``."""

    def __call__(self, parser, namespace, values, option_string=None):
        for word in values or ():
            key, equals, value = word.partition('=')
            if not key or not equals:
                raise argparse.ArgumentError(
                    self, f'must be key=value words, got {excerpt(word)}')
            try:  # mmengine asserts balanced brackets, recurses on nesting
                self._parse_iterable(value)
            except (AssertionError, RecursionError):
                raise argparse.ArgumentError(
                    self, f'{key}: unbalanced or too deeply nested brackets '
                    f'in {excerpt(value)}') from None
        super().__call__(parser, namespace, values, option_string)
        options = getattr(namespace, self.dest)
        for key in SPIKE_SETTING_KINDS.keys() & options.keys():
            try:
                _as_env_value(key, options[key])
            except ArgumentError as err:
                raise argparse.ArgumentError(
                    self, f'{key} must be {err.expected}, got '
                    f'{excerpt(options[key])}') from None


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """A tool's ``--cfg-options`` (:class:`ConfigOptions`), for
    :func:`load_config`."""
    parser.add_argument(
        '--cfg-options', nargs='+', action=ConfigOptions, default={},
        help='override config settings, key=value; num_steps, data_root and '
        'crop_size re-derive every field that depends on them')


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


def config_from_args(args: argparse.Namespace) -> Config:
    """The config of ``args.config`` set up for an mmengine ``Runner``.

    Applies ``--cfg-options``, the launcher and the work dir (default
    ``./work_dirs/<config name>``), and sets ``LOCAL_RANK`` if unset;
    distributed runs on a machine without CUDA use gloo
    (:func:`~wgse_mmseg.utils.distributed.prepare_launcher`).
    """
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


def build_runner(cfg: Config) -> Runner:
    """The runner of ``cfg``, as MMSeg's tools build it: the config's
    ``runner_type`` (the shipped configs': ``SpikeRunner``) where it names
    one, else mmengine's ``Runner``."""
    if 'runner_type' in cfg:
        return RUNNERS.build(cfg)
    return Runner.from_cfg(cfg)
