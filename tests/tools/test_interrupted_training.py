"""Training under load: a SIGKILL while a checkpoint is written, and a
corrupted sample met by a data-loader worker."""
import os
import os.path as osp
import re
import subprocess
import sys

import pytest

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
HERE = osp.dirname(osp.abspath(__file__))
CONFIG = osp.join(
    ROOT, 'configs',
    'segformer_b0_wgse.py')


#: a checkpoint every epoch, all kept; no validation
EVERY_EPOCH = ('train_cfg.val_interval=100',
               'default_hooks.checkpoint.interval=1',
               'default_hooks.checkpoint.max_keep_ckpts=5')


def _run(cmd, cwd):
    env = dict(os.environ, OMP_NUM_THREADS='1')
    env.pop('TRITON_INTERPRET', None)
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=900)


@pytest.mark.long(22)
def test_resume_after_a_kill_during_a_checkpoint_save(tiny_spike_dataset,
                                                      tiny_run_options,
                                                      tmp_path):
    options = tiny_run_options(tiny_spike_dataset, 'train_cfg.max_epochs=3',
                               *EVERY_EPOCH)
    work = tmp_path / 'work'
    proc = _run([sys.executable,
                 osp.join(HERE, 'kill_during_checkpoint_run.py'),
                 '2', '--', CONFIG, '--work-dir', str(work)] + options,
                cwd=tmp_path)
    assert proc.returncode == -9, proc.stderr[-3000:]
    # the half-written checkpoint never took a checkpoint's name
    assert (work / 'epoch_1.pth').is_file()
    assert not (work / 'epoch_2.pth').exists()
    assert (work / 'last_checkpoint').read_text().strip().endswith(
        'epoch_1.pth')
    proc = _run([sys.executable, osp.join(ROOT, 'tools', 'train.py'), CONFIG,
                 '--work-dir', str(work), '--resume'] + options,
                cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert re.search(r'resumed epoch: 1, iter: 2', proc.stdout + proc.stderr)
    assert (work / 'epoch_3.pth').is_file()
    assert not [p for p in os.listdir(work) if p.startswith('.tmp-')]


def test_a_corrupted_sample_with_workers_names_the_file(tiny_spike_dataset,
                                                        tiny_run_options,
                                                        tmp_path):
    import shutil
    copy = tmp_path / 'data'
    shutil.copytree(tiny_spike_dataset, copy)
    spikes = sorted((copy / 'spike' / 'train').rglob('*.spk'))
    victim = spikes[len(spikes) // 2]
    # The same size with a broken header: the dataset's start-up check of
    # each sample's marker (sizes) passes it, so a worker meets it. (A
    # truncated file is skipped at start-up: tests/datasets.)
    with open(victim, 'r+b') as f:
        f.write(b'\0' * 8)
    proc = _run([sys.executable, osp.join(ROOT, 'tools', 'train.py'), CONFIG,
                 '--work-dir', str(tmp_path / 'work')] +
                tiny_run_options(copy, 'train_cfg.max_epochs=1', *EVERY_EPOCH,
                                 workers=2), cwd=tmp_path)
    assert proc.returncode != 0
    assert str(victim) in proc.stderr
    assert 'SpikeFileError' in proc.stderr
