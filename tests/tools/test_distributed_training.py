"""Distributed training on CPUs (gloo): two processes keep the WGSE
enhancer (a module of the data preprocessor, which runs it inside
``MMDistributedDataParallel.train_step``) identical, and match one process
with the same total batch."""
import os
import os.path as osp
import re
import socket
import subprocess
import sys

import pytest
import torch


ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
DRIVER = osp.join(osp.dirname(osp.abspath(__file__)), 'ddp_training_run.py')
CONFIG = osp.join(ROOT, 'configs',
                  'segformer_b0_wgse.py')


def _free_port():
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


def _run(cmd, cwd, **extra):
    env = dict(os.environ, OMP_NUM_THREADS='1', CUDA_VISIBLE_DEVICES='',
               **extra)
    env.pop('TRITON_INTERPRET', None)
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-6000:]
    return proc.stdout + proc.stderr


#: 2 epochs of the 4 training samples, no validation, no checkpoints
SHORT_RUN = ('train_cfg.max_epochs=2', 'train_cfg.val_interval=100',
             'default_hooks.checkpoint.interval=100')


@pytest.mark.long(35)
def test_two_processes_keep_the_enhancer_in_sync(tiny_spike_dataset,
                                                 tiny_run_options, tmp_path):
    data = tiny_spike_dataset
    two, one = tmp_path / 'two', tmp_path / 'one'
    two.mkdir()
    one.mkdir()
    log = _run([sys.executable, '-m', 'torch.distributed.run',
                '--nproc_per_node=2', f'--master_port={_free_port()}',
                DRIVER, CONFIG, str(two), '--launcher', 'pytorch',
                '--work-dir', str(tmp_path / 'work_two')] +
               tiny_run_options(data, *SHORT_RUN, batch_size=1),
               cwd=tmp_path)
    assert 'gloo' in log
    _run([sys.executable, DRIVER, CONFIG, str(one), '--work-dir',
          str(tmp_path / 'work_one')] +
         tiny_run_options(data, *SHORT_RUN, batch_size=2), cwd=tmp_path)
    rank0 = torch.load(two / 'rank0.pt', weights_only=False)
    rank1 = torch.load(two / 'rank1.pt', weights_only=False)
    single = torch.load(one / 'rank0.pt', weights_only=False)
    assert rank0['wrapper'] == 'CPUDistributedDataParallel'
    assert rank0['world_size'] == 2 and single['world_size'] == 1
    moved = [name for name, value in rank0['after'].items()
             if not torch.equal(value, rank0['before'][name])]
    assert len(moved) > len(rank0['after']) // 2  # 4 steps of SGD
    # The two runs add the batch's gradients in different orders (an
    # all-reduce of two per-sample sums against one sum over the batch), so
    # their updates agree to float32 rounding of sums with cancellation, not
    # to a fixed number, and a parameter whose gradient cancels (a 1x1 bias)
    # can differ by 10% of its own tiny update: the updates of all the
    # parameters together are held to 5% of their norm, where gradients
    # summed rather than averaged, or not synchronised, are off by about
    # the update itself.
    two_steps, one_step = [], []
    for name, value in rank0['after'].items():
        assert torch.equal(value, rank1['after'][name]), name
        torch.testing.assert_close(rank0['before'][name],
                                   single['before'][name])
        two_steps.append((value - rank0['before'][name]).flatten())
        one_step.append((single['after'][name] -
                         single['before'][name]).flatten())
    two_steps, one_step = torch.cat(two_steps), torch.cat(one_step)
    error = (two_steps - one_step).norm() / one_step.norm()
    assert error < 0.05, error


@pytest.mark.long(50)
def test_dist_train_and_dist_test_scripts_on_cpu(tiny_spike_dataset,
                                                 tiny_run_options, tmp_path):
    """MMSeg's interface as the README gives it, ``bash tools/dist_train.sh
    configs/pspnet_wgse.py 2`` from the repository root, two processes with
    gloo; the configs' SyncBN switch is set aside on CPUs, with a warning."""
    work = tmp_path / 'work'
    # batch 2 a process: PSPNet's pooled 1x1 branch needs two values per
    # channel for BN in training (plain BN on CPUs, not SyncBN)
    options = tiny_run_options(tiny_spike_dataset, 'train_cfg.max_epochs=1',
                               batch_size=2)
    log = _run(['bash', 'tools/dist_train.sh', 'configs/pspnet_wgse.py',
                '2', '--work-dir', str(work)] + options, cwd=ROOT,
               PYTHON=sys.executable, PORT=str(_free_port()))
    assert "sync_bn='torch' ignored" in log
    assert (work / 'epoch_1.pth').is_file()
    log = _run(['bash', 'tools/dist_test.sh', 'configs/pspnet_wgse.py',
                str(work / 'epoch_1.pth'), '2', '--work-dir',
                str(tmp_path / 'test')] + options, cwd=ROOT,
               PYTHON=sys.executable, PORT=str(_free_port()))
    assert re.search(r'mIoU: [\d.]+', log), log[-3000:]


def test_a_distributed_launcher_without_torchrun_says_how_to_start(tmp_path):
    from argparse import Namespace
    from wgse_mmseg.utils.config import config_from_args
    if torch.cuda.is_available():
        pytest.skip('the gloo path is for machines without CUDA')
    env_names = ('RANK', 'WORLD_SIZE', 'MASTER_ADDR', 'MASTER_PORT')
    saved = {name: os.environ.pop(name, None) for name in env_names}
    try:
        with pytest.raises(ValueError, match='tools/dist_train.sh'):
            config_from_args(Namespace(
                config=CONFIG, cfg_options=None, launcher='pytorch',
                work_dir=str(tmp_path), local_rank=0))
        with pytest.raises(ValueError, match='slurm needs GPUs'):
            config_from_args(Namespace(
                config=CONFIG, cfg_options=None, launcher='slurm',
                work_dir=str(tmp_path), local_rank=0))
    finally:
        os.environ.update({k: v for k, v in saved.items() if v is not None})
