"""tools/train_reconstruction.sh: the shipped weights' recipe, end to end,
with two iterations on a small REDS-layout folder."""
import os
import os.path as osp
import subprocess
import sys

import cv2
import numpy as np
import pytest
import torch

import wgse_mmseg
from wgse_mmseg.fileio.spike_files import save_spikes

wgse_mmseg.register_all_modules()
from wgse_mmseg.models.reconstruction import load_reconstructor  # noqa: E402

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SCRIPT = osp.join(ROOT, 'tools', 'train_reconstruction.sh')


def _reds_dat_folder(root, size=(72, 96), steps=61):
    rng = np.random.default_rng(0)
    os.makedirs(osp.join(root, 'spike'))
    os.makedirs(osp.join(root, 'gt'))
    gt = rng.integers(0, 256, size, dtype=np.uint8)
    spikes = (rng.random((steps, *size)) < gt / 255 * 0.6).astype(np.uint8)
    save_spikes(osp.join(root, 'spike', 'clip.dat'), spikes)
    cv2.imwrite(osp.join(root, 'gt', 'clip.png'), gt)
    return root


def _run(tmp_path, **env):
    env = dict(dict(os.environ, PY=sys.executable, ITERS='2',
                    WORK=str(tmp_path / 'work'),
                    IMAGES=str(tmp_path / 'images'),
                    OUT=str(tmp_path / 'weights.pth')), **env)
    return subprocess.run(['bash', SCRIPT], capture_output=True, text=True,
                          env=env, timeout=900)


@pytest.mark.long(60)
def test_the_recipe_runs_start_to_finish(tmp_path):
    reds = _reds_dat_folder(str(tmp_path / 'reds'))
    proc = _run(tmp_path, REDS_TRAIN=reds, REDS_TEST=reds)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    log = proc.stdout + proc.stderr
    # it began from the earlier shipped weights, on both data sources
    assert 'wgse_reconstruction_cpu_v1.pth' in log
    assert 'Saving checkpoint at 2 iterations' in log
    assert 'exported' in proc.stdout
    model = load_reconstructor(str(tmp_path / 'weights.pth'))
    assert model.num_steps == 41
    # the scoring table of the benchmark, on REDS_TEST
    assert '| WGSE |' in proc.stdout and '| TFP |' in proc.stdout
    # a re-run resumes from the finished run instead of training again;
    # without a REDS_TEST folder it scores nothing
    again = _run(tmp_path, REDS_TRAIN=reds,
                 REDS_TEST=str(tmp_path / 'no_test_folder'))
    assert again.returncode == 0, again.stderr[-3000:]
    log = again.stdout + again.stderr
    assert 'resumed from the latest checkpoint' in log and 'iter_2.pth' in log
    assert 'Saving checkpoint at' not in log
    assert 'exported' in again.stdout and '| WGSE |' not in again.stdout
    assert torch.load(tmp_path / 'weights.pth', weights_only=True)[
        'meta']['model']['type'] == 'SpikeReconstructor'


def test_bad_settings_are_refused_before_any_work(tmp_path):
    proc = _run(tmp_path, REDS_TRAIN=str(tmp_path / 'missing'))
    assert proc.returncode == 2 and 'REDS_TRAIN' in proc.stderr
    reds = _reds_dat_folder(str(tmp_path / 'reds'))
    proc = _run(tmp_path, REDS_TRAIN=reds, ITERS='two')
    assert proc.returncode == 2 and 'ITERS' in proc.stderr
    assert not osp.exists(tmp_path / 'work')
