"""Training under load: a SIGKILL while a checkpoint is written, and a
corrupted sample met by a data-loader worker."""
import os
import os.path as osp
import re
import subprocess
import sys

import pytest

from wgse_mmseg.datasets.synthetic import make_synthetic_dataset

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
HERE = osp.dirname(osp.abspath(__file__))
CONFIG = osp.join(ROOT, 'configs', 'segformer_mit-b0_wgse_1xb4-100e_spike-cityscapes-256x512.py')


@pytest.fixture(scope='module')
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp('interrupted_data')
    make_synthetic_dataset(str(root), num_train=4, num_val=1, height=32,
                           width=64, num_steps=9, progress=False)
    return root


def _options(data, workers=0, epochs=3):
    loaders = [f'{split}_dataloader.{key}={value}'
               for split in ('train', 'val')
               for key, value in (('num_workers', workers),
                                  ('persistent_workers', False))]
    return ['--cfg-options', f'data_root={data}', 'num_steps=9',
            'crop_size=32,64', 'train_dataloader.batch_size=2',
            f'train_cfg.max_epochs={epochs}', 'train_cfg.val_interval=100',
            'default_hooks.checkpoint.interval=1',
            'default_hooks.checkpoint.max_keep_ckpts=5'] + loaders


def _run(cmd, cwd):
    env = dict(os.environ, OMP_NUM_THREADS='1')
    env.pop('TRITON_INTERPRET', None)
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=900)


def test_resume_after_a_kill_during_a_checkpoint_save(data, tmp_path):
    work = tmp_path / 'work'
    proc = _run([sys.executable, osp.join(HERE, 'kill_during_checkpoint_run.py'),
                 '2', '--', CONFIG, '--work-dir', str(work)] + _options(data),
                cwd=tmp_path)
    assert proc.returncode == -9, proc.stderr[-3000:]
    # the half-written checkpoint never took a checkpoint's name
    assert (work / 'epoch_1.pth').is_file()
    assert not (work / 'epoch_2.pth').exists()
    assert (work / 'last_checkpoint').read_text().strip().endswith(
        'epoch_1.pth')
    proc = _run([sys.executable, osp.join(ROOT, 'tools', 'train.py'), CONFIG,
                 '--work-dir', str(work), '--resume'] + _options(data),
                cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert re.search(r'resumed epoch: 1, iter: 2', proc.stdout + proc.stderr)
    assert (work / 'epoch_3.pth').is_file()
    assert not [p for p in os.listdir(work) if p.startswith('.tmp-')]


def test_a_corrupted_sample_with_workers_names_the_file(data, tmp_path):
    import shutil
    copy = tmp_path / 'data'
    shutil.copytree(data, copy)
    spikes = sorted((copy / 'spike' / 'train').rglob('*.spk'))
    victim = spikes[len(spikes) // 2]
    with open(victim, 'r+b') as f:
        f.truncate(f.seek(0, 2) // 2)
    proc = _run([sys.executable, osp.join(ROOT, 'tools', 'train.py'), CONFIG,
                 '--work-dir', str(tmp_path / 'work')] +
                _options(copy, workers=2, epochs=1), cwd=tmp_path)
    assert proc.returncode != 0
    assert str(victim) in proc.stderr
    assert 'SpikeFileError' in proc.stderr
