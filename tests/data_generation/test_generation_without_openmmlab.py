"""Data generation (the Cityscapes converter, the synthetic scenes, REDS-style
views) and its two tools import and run where mmengine, mmsegmentation and
mmcv cannot be imported, as the core does
(tests/core/test_without_openmmlab.py; the blocker is conftest's
``without_openmmlab``, a ``sitecustomize`` every process of the run loads)."""
import json
import os
import os.path as osp
import subprocess
import sys

import cv2
import numpy as np

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SCRIPT = '''
import json, sys
import numpy as np
from wgse_mmseg.data_generation.cityscapes_conversion import (
    ConversionSettings, convert_cityscapes)
from wgse_mmseg.data_generation.synthetic import make_synthetic_dataset
from wgse_mmseg.data_generation.views import render_trajectory
root, out = sys.argv[1:3]
counts = convert_cityscapes(root, out + '/converted', ConversionSettings(
    height=16, width=32, num_steps=5), splits=('val', ), progress=False)
written = make_synthetic_dataset(out + '/synthetic', 1, 1, 16, 32, 5,
                                 progress=False)
view = render_trajectory(np.random.default_rng(0).random((20, 30)), (8, 8),
                         5, np.random.default_rng(1))
print(json.dumps(dict(
    counts=counts, written=written, view=list(view.shape),
    loaded=sorted({m.split('.')[0] for m in sys.modules
                   if m.split('.')[0] in ('mmengine', 'mmseg', 'mmcv')}))))
'''


def _cityscapes(root):
    """One annotated frame, no sequence: the static model."""
    rng = np.random.default_rng(0)
    for tree, suffix, image in (
            ('leftImg8bit', 'leftImg8bit',
             rng.integers(0, 256, (32, 64, 3), dtype=np.uint8)),
            ('gtFine', 'gtFine_labelIds',
             rng.choice(np.array([7, 8, 11, 23, 26], np.uint8), (32, 64)))):
        folder = osp.join(root, tree, 'val', 'bonn')
        os.makedirs(folder)
        assert cv2.imwrite(
            osp.join(folder, f'bonn_000000_000019_{suffix}.png'), image)


def test_generators_run_without_openmmlab(without_openmmlab, tmp_path):
    root = str(tmp_path / 'cityscapes')
    _cityscapes(root)
    env = without_openmmlab
    hidden = subprocess.run([sys.executable, '-c', 'import mmseg'],
                            capture_output=True, text=True, env=env)
    assert 'hidden' in hidden.stderr  # the blocker is in force
    proc = subprocess.run(
        [sys.executable, '-c', SCRIPT, root, str(tmp_path / 'api')],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report['counts'] == dict(sequence=0, static=1, skipped=0)
    assert report['written'] == 2 and report['view'] == [5, 8, 8]
    assert report['loaded'] == []  # nothing of the stack was imported
    assert osp.getsize(tmp_path / 'api' / 'converted' / 'spike' / 'val' /
                       'bonn' / 'bonn_000000_000019_spike.spk') > 0


def test_the_tools_run_without_openmmlab(without_openmmlab, tmp_path):
    root = str(tmp_path / 'cityscapes')
    _cityscapes(root)
    tools = osp.join(ROOT, 'tools', 'dataset_converters')
    for command in (
            ['spike_cityscapes.py', root, str(tmp_path / 'converted'),
             '--height', '16', '--width', '32', '--num-steps', '5',
             '--splits', 'val', '--shard', '1/1'],
            ['make_synthetic_dataset.py', str(tmp_path / 'synthetic'),
             '--num-train', '1', '--num-val', '0', '--height', '16',
             '--width', '32', '--num-steps', '5']):
        proc = subprocess.run(
            [sys.executable, osp.join(tools, command[0])] + command[1:],
            capture_output=True, text=True, env=without_openmmlab,
            cwd=tmp_path, timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert 'error' not in proc.stderr.lower()
    assert osp.exists(tmp_path / 'converted' / 'spike' / 'val' / 'bonn' /
                      'bonn_000000_000019_spike.json')
    assert osp.exists(tmp_path / 'synthetic' / 'spike' / 'train' / 'synth' /
                      'synth_000000_000019_spike.json')
