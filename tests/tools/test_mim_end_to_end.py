"""From a built and installed package: mim train, resume, tools/test.py.

The package is built as a wheel from a copy of the repository and installed
into a fresh directory placed first on PYTHONPATH, so `mim` finds the
installed copy's `.mim/tools/train.py` and `.mim/configs/` (not the
repository's), as a user's regular install would.
"""
import os
import os.path as osp
import re
import shutil
import subprocess
import sys

import pytest

from wgse_mmseg.datasets.synthetic import make_synthetic_dataset

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
BIN = osp.dirname(sys.executable)


def run(cmd, cwd, env, timeout=900):
    result = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True,
                            text=True, timeout=timeout)
    log = result.stdout + result.stderr
    assert result.returncode == 0, f'{cmd} failed:\n{log[-6000:]}'
    return log


@pytest.fixture(scope='module')
def installed(tmp_path_factory):
    """PYTHONPATH entry holding wgse_mmseg installed from a wheel."""
    work = tmp_path_factory.mktemp('install')
    source = work / 'src'
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(
        '.venv', '.git', 'work_dirs', 'data', '__pycache__', '*.egg-info',
        '.mim', 'build', '.pytest_cache', '.hypothesis'))
    env = dict(os.environ)
    run([sys.executable, '-m', 'pip', 'wheel', '--no-deps',
         '--no-build-isolation', '-q', '-w', str(work / 'dist'), str(source)],
        cwd=work, env=env)
    wheel = next((work / 'dist').glob('wgse_mmseg-*.whl'))
    target = work / 'site'
    run([sys.executable, '-m', 'pip', 'install', '--no-deps', '-q',
         '--target', str(target), str(wheel)], cwd=work, env=env)
    assert (target / 'wgse_mmseg' / '.mim' / 'configs' /
            'pspnet_wgse.py').is_file()
    assert (target / 'wgse_mmseg' / '.mim' / 'tools' / 'train.py').is_file()
    return target


def test_mim_train_resume_and_test_from_installed_package(installed,
                                                          tmp_path):
    data = tmp_path / 'data'
    make_synthetic_dataset(str(data), num_train=2, num_val=1, height=32,
                           width=64, num_steps=9, progress=False)
    env = dict(os.environ, PYTHONPATH=str(installed),
               PATH=BIN + os.pathsep + os.environ.get('PATH', ''))
    options = ['--cfg-options', f'data_root={data}', 'num_steps=9',
               'crop_size=32,64', 'train_dataloader.batch_size=2',
               'train_dataloader.num_workers=0',
               'train_dataloader.persistent_workers=False',
               'val_dataloader.num_workers=0',
               'val_dataloader.persistent_workers=False',
               'train_cfg.val_interval=1', 'default_hooks.checkpoint.interval=1',
               'default_hooks.logger.interval=1']
    work_dir = tmp_path / 'work'
    mim = [osp.join(BIN, 'mim'), 'train', 'wgse_mmseg',
           'configs/pspnet_wgse.py', '--gpus', '0', '--launcher', 'none',
           '--work-dir', str(work_dir)]
    log = run(mim + options + ['train_cfg.max_epochs=1'], cwd=tmp_path,
              env=env)
    assert str(installed) in log  # the installed copy's config was used
    assert (work_dir / 'epoch_1.pth').is_file()

    log = run(mim + ['--resume'] + options + ['train_cfg.max_epochs=2'],
              cwd=tmp_path, env=env)
    assert re.search(r'resumed epoch: 1, iter: 1', log), log[-3000:]
    assert (work_dir / 'epoch_2.pth').is_file()

    test_script = installed / 'wgse_mmseg' / '.mim' / 'tools' / 'test.py'
    config = installed / 'wgse_mmseg' / '.mim' / 'configs' / 'pspnet_wgse.py'
    log = run([sys.executable, str(test_script), str(config),
               str(work_dir / 'epoch_2.pth'), '--work-dir',
               str(tmp_path / 'test')] + options[:4] +
              ['test_dataloader.num_workers=0',
               'test_dataloader.persistent_workers=False'],
              cwd=tmp_path, env=env)
    metrics = re.search(r'aAcc: ([\d.]+)\s+mIoU: ([\d.]+)\s+mAcc: ([\d.]+)',
                        log)
    assert metrics, log[-3000:]
    assert all(0 <= float(v) <= 100 for v in metrics.groups())
