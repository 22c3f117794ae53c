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
import copy
import os
import os.path as osp
from typing import TYPE_CHECKING, Dict, Optional

from .._openmmlab import prepare_mmseg_layer
from ..core.arguments import Choice, Integer, Path
from ..core.limits import MAX_WORKERS, excerpt
from ..core.output_folder import note_input
from .spike_settings import (SPIKE_SETTINGS, SpikeSettingsError,
                             apply_spike_settings, check_setting)

if TYPE_CHECKING:
    from mmengine.config import Config
    from mmengine.runner import Runner

__all__ = []

#: ``--cfg-options`` key -> the declaration of its value (from
#: :data:`~wgse_mmseg.utils.spike_settings.SPIKE_SETTINGS`)
SPIKE_SETTING_KINDS = {setting.name: setting.kind
                       for setting in SPIKE_SETTINGS}


def load_config(path: str, cfg_options: Optional[Dict] = None) -> 'Config':
    """``Config.fromfile(path)`` with ``cfg_options`` applied.

    ``num_steps``, ``data_root`` and ``crop_size`` in ``cfg_options`` go to
    the fields that carry them, before the other keys are merged with
    ``Config.merge_from_dict`` (so ``val_dataloader.dataset.data_root=A``
    beside ``data_root=B`` keeps ``A``); then the fields are checked against
    the settings once more (see :mod:`wgse_mmseg.utils.spike_settings`).
    Sets the MMSeg layer up first (:func:`~wgse_mmseg._openmmlab.
    prepare_mmseg_layer`), which the configs' ``mmseg::`` bases need on the
    onedl stack.
    """
    if not osp.isfile(path):
        raise FileNotFoundError(f'{path}: no such config file')
    note_input(path)
    prepare_mmseg_layer('load_config')
    from mmengine.config import Config
    options = dict(cfg_options or {})
    settings = {setting.name: options.pop(setting.name)
                for setting in SPIKE_SETTINGS if setting.name in options}
    cfg = Config.fromfile(path)
    apply_spike_settings(cfg, settings)
    if options:
        cfg.merge_from_dict(options)
        apply_spike_settings(cfg)
    return cfg


class ConfigOptions(argparse.Action):
    """mmengine's ``DictAction`` (``key=value`` words, values read as
    Python literals by its parser, imported when a word is read), refusing a
    word it cannot read and checking the spike settings against
    :data:`SPIKE_SETTING_KINDS` as the command line is parsed, so argparse
    exits with ``argument --cfg-options: num_steps must be ...``."""

    def __call__(self, parser, namespace, values, option_string=None):
        from mmengine.config import DictAction
        options = copy.copy(getattr(namespace, self.dest, None) or {})
        for word in values or ():
            key, equals, value = word.partition('=')
            if not key or not equals:
                raise argparse.ArgumentError(
                    self, f'must be key=value words, got {excerpt(word)}')
            try:  # mmengine asserts balanced brackets, recurses on nesting
                options[key] = DictAction._parse_iterable(value)
            except (AssertionError, RecursionError):
                raise argparse.ArgumentError(
                    self, f'{key}: unbalanced or too deeply nested brackets '
                    f'in {excerpt(value)}') from None
        setattr(namespace, self.dest, options)
        for key in SPIKE_SETTING_KINDS.keys() & options.keys():
            try:
                check_setting(key, options[key], text=True)
            except SpikeSettingsError as err:
                raise argparse.ArgumentError(self, str(err)) from None


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
