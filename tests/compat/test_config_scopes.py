"""A config anywhere on disk inherits the package's bases by scope,
``wgse_mmseg::_base_/...``, with a model the package does not ship
(MMSeg's BiSeNetV2), and trains with the package's tools."""
import os
import os.path as osp
import subprocess
import sys

import pytest

from wgse_mmseg.compat import config_scopes
from wgse_mmseg.utils.config import load_config

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
#: the package's bases a user's config names (datasets, runtime, schedule)
BASES = ('_base_/datasets/spike_cityscapes.py', '_base_/default_runtime.py',
         '_base_/schedules/adamw_warmup_100e.py')
#: MMSeg's BiSeNetV2 with the spike preprocessor and T input channels
BODY = ("model = dict(data_preprocessor=dict(\n"
        "    _delete_=True, **_base_.spike_data_preprocessor),\n"
        "    backbone=dict(in_channels={{_base_.num_steps}}))\n")


def _config(folder, bases) -> str:
    path = folder / 'bisenetv2_spikes.py'
    bases = ['mmseg::_base_/models/bisenetv2.py', *bases]
    path.write_text(f'_base_ = {bases!r}\n' + BODY)
    return str(path)


def test_scoped_bases_load_as_their_files_do(tmp_path):
    """The scoped bases give the config the same bases named by their
    absolute paths in the checkout give (the reference), settings from the
    command line reaching them alike."""
    (tmp_path / 'scoped').mkdir()
    (tmp_path / 'absolute').mkdir()
    scoped = _config(tmp_path / 'scoped',
                     [f'wgse_mmseg::{base}' for base in BASES])
    absolute = _config(tmp_path / 'absolute',
                       [osp.join(ROOT, 'configs', base) for base in BASES])
    options = dict(num_steps=9, crop_size=(32, 64))
    cfg, reference = (load_config(path, options)
                      for path in (scoped, absolute))
    assert cfg.to_dict() == reference.to_dict()
    assert cfg.model.type == 'EncoderDecoder'
    assert cfg.model.backbone.type == 'BiSeNetV2'
    assert cfg.model.backbone.in_channels == 9
    assert cfg.model.data_preprocessor.type == 'SpikeSegDataPreProcessor'
    assert cfg.train_dataloader.dataset.type == 'SpikeCityscapesDataset'
    assert cfg.runner_type == 'SpikeRunner'


def test_a_missing_scoped_base_is_named(tmp_path):
    config = _config(tmp_path, ['wgse_mmseg::_base_/datasets/nothing.py'])
    with pytest.raises(FileNotFoundError,
                       match=r'bisenetv2_spikes\.py: base wgse_mmseg::_base_/'
                       r'datasets/nothing\.py: no such config'):
        load_config(config)


@pytest.mark.parametrize('layout', ['mim', 'checkout', 'neither'])
def test_the_configs_folder_of_each_install_mode(tmp_path, monkeypatch,
                                                 layout):
    """``.mim/configs`` of an install that carries it (regular, egg-link),
    else the checkout's ``configs/`` (PEP 660 editable, PYTHONPATH)."""
    package = tmp_path / 'wgse_mmseg'
    (package / 'compat').mkdir(parents=True)
    expected = {'mim': package / '.mim' / 'configs',
                'checkout': tmp_path / 'configs'}.get(layout)
    if expected is not None:
        expected.mkdir(parents=True)
    monkeypatch.setattr(config_scopes, '__file__',
                        str(package / 'compat' / 'config_scopes.py'))
    if expected is None:
        with pytest.raises(FileNotFoundError, match='reinstall wgse_mmseg'):
            config_scopes.package_configs()
    else:
        assert config_scopes.package_configs() == str(expected)


def _one_epoch(tmp_path, dataset, run_options):
    """The BiSeNetV2 config by scope in ``tmp_path``, its work dir and the
    options of one epoch on ``dataset`` with a checkpoint."""
    config = _config(tmp_path, [f'wgse_mmseg::{base}' for base in BASES])
    options = run_options(dataset, 'train_cfg.max_epochs=1',
                          'train_cfg.val_interval=2',
                          'default_hooks.checkpoint.interval=1',
                          batch_size=4)
    return config, tmp_path / 'work', options


@pytest.mark.long(40)
def test_a_config_elsewhere_trains_with_the_package_tool(
        tmp_path, tiny_spike_dataset, tiny_run_options):
    """tools/train.py (what ``mim train wgse_mmseg`` runs) trains the
    BiSeNetV2 config of another folder one iteration, its checkpoint
    written."""
    config, work_dir, options = _one_epoch(tmp_path, tiny_spike_dataset,
                                           tiny_run_options)
    result = subprocess.run(
        [sys.executable, osp.join(ROOT, 'tools', 'train.py'), config,
         '--work-dir', str(work_dir), *options],
        cwd=tmp_path, capture_output=True, text=True, timeout=600,
        env=dict(os.environ, PYTHONPATH=ROOT))
    log = result.stdout + result.stderr
    assert result.returncode == 0, log[-4000:]
    assert (work_dir / 'epoch_1.pth').is_file(), log[-4000:]
    assert 'BiSeNetV2' in log


@pytest.mark.long(30)
def test_mim_trains_a_config_elsewhere(tmp_path, tiny_spike_dataset,
                                       tiny_run_options):
    """``mim train wgse_mmseg`` (each stack's mim, the README's install)
    trains the BiSeNetV2 config of another folder one iteration."""
    bin_dir = osp.dirname(sys.executable)
    env = dict(os.environ,
               PATH=bin_dir + os.pathsep + os.environ.get('PATH', ''))
    env.pop('PYTHONPATH', None)  # the user's own shell
    found = subprocess.run(
        [sys.executable, '-c', 'from mim.utils import get_installed_path; '
         "print(get_installed_path('wgse_mmseg'))"], cwd=tmp_path, env=env,
        capture_output=True, text=True).stdout.strip()
    if found not in (osp.join(ROOT, 'wgse_mmseg'), ROOT):
        pytest.skip(f'mim finds wgse_mmseg at {found!r}, not in this '
                    f'checkout (tests/tools/test_mim_end_to_end.py says so)')
    config, work_dir, options = _one_epoch(tmp_path, tiny_spike_dataset,
                                           tiny_run_options)
    result = subprocess.run(
        [osp.join(bin_dir, 'mim'), 'train', 'wgse_mmseg', config, '--gpus',
         '0', '--launcher', 'none', '--work-dir', str(work_dir), *options],
        cwd=tmp_path, capture_output=True, text=True, timeout=600, env=env)
    log = result.stdout + result.stderr
    assert result.returncode == 0, log[-4000:]
    assert (work_dir / 'epoch_1.pth').is_file(), log[-4000:]
