"""MMSeg's inferencer on spike files."""
import os.path as osp

import cv2
import numpy as np
import pytest

from wgse_mmseg.apis.inferencer import SpikeSegInferencer
from wgse_mmseg.fileio.spike_files import save_spikes
from wgse_mmseg.engine import spike_clip_image
from wgse_mmseg.utils.config import load_config

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


def test_inferencer_predicts_and_draws_spike_files(tmp_path):
    cfg = load_config(osp.join(ROOT, 'configs', 'segformer_b0_wgse.py'),
                      dict(num_steps=9))
    rng = np.random.default_rng(0)
    paths = []
    for name in ('a', 'b'):
        paths.append(str(tmp_path / f'{name}.npy'))
        save_spikes(paths[-1], (rng.random((15, 32, 64)) < 0.3).astype(
            np.uint8))
    inferencer = SpikeSegInferencer(cfg, device='cpu')
    # opacity 0: the drawing is the stream's image alone, exactly
    samples = inferencer(paths, out_dir=str(tmp_path / 'out'),
                         return_datasamples=True, opacity=0.0)
    assert [s.img_path for s in samples] == paths
    assert all(s.pred_sem_seg.data.shape == (1, 32, 64) for s in samples)
    drawn = cv2.imread(str(tmp_path / 'out' / 'vis' / 'a.png'))
    assert drawn.shape == (32, 64, 3)
    # the stream's centre 9 frames as a TFP image
    np.testing.assert_array_equal(drawn, spike_clip_image(paths[0], 9))
    # and the label maps MMSeg's inferencer returns by default
    masks = inferencer(paths[1])['predictions']
    assert masks.shape == (32, 64) and masks.dtype.kind in 'iu'


def test_inferencer_executes_no_config_text_from_a_checkpoint(tmp_path):
    """Without a config, mmengine's inferencer would execute the config text
    the checkpoint carries (``Config.fromstring`` of ``meta['cfg']``)."""
    import torch
    marker = tmp_path / 'pwned'
    path = str(tmp_path / 'downloaded.pth')
    torch.save(dict(state_dict={}, meta=dict(cfg=(
        f"open(r'{marker}', 'w').write('ran')\n"
        f"model = dict(type='SpikeEncoderDecoder')\n"))), path)
    with pytest.raises(ValueError, match='downloaded.pth.*not executed'):
        SpikeSegInferencer(None, weights=path, device='cpu')
    assert not marker.exists()


def test_python_predicts_what_tools_test_py_predicts(tiny_spike_dataset,
                                                     tiny_run_options,
                                                     tmp_path):
    """``wgse_mmseg.load_config`` with the tools' options, then MMSeg's
    ``init_model`` and ``inference_model``: the label maps
    ``tools/test.py --out`` writes for the same checkpoint and options."""
    import subprocess
    import sys

    import torch
    from mmengine.registry import init_default_scope

    import wgse_mmseg
    from mmseg.apis import inference_model, init_model
    from mmseg.registry import MODELS
    config = osp.join(ROOT, 'configs', 'segformer_b0_wgse.py')
    options = dict(data_root=str(tiny_spike_dataset), num_steps=9,
                   crop_size='32,64')
    cfg = wgse_mmseg.load_config(config, options)
    init_default_scope('mmseg')
    torch.manual_seed(3)
    checkpoint = str(tmp_path / 'model.pth')
    torch.save(dict(state_dict=MODELS.build(cfg.model).state_dict(),
                    meta={}), checkpoint)
    out = tmp_path / 'masks'
    proc = subprocess.run(
        [sys.executable, osp.join(ROOT, 'tools', 'test.py'), config,
         checkpoint, '--out', str(out), '--work-dir', str(tmp_path / 'w')] +
        tiny_run_options(tiny_spike_dataset), cwd=ROOT, capture_output=True,
        text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    model = init_model(wgse_mmseg.load_config(config, options), checkpoint,
                       device='cpu')
    spikes = sorted(tiny_spike_dataset.glob('spike/val/*/*_spike.spk'))
    assert spikes
    for path in spikes:
        predicted = inference_model(model, str(path)).pred_sem_seg.data[0]
        saved = cv2.imread(str(out / (path.name.split('.')[0] + '.png')),
                           cv2.IMREAD_UNCHANGED)
        assert saved is not None, sorted(p.name for p in out.iterdir())
        assert len(np.unique(saved)) > 1  # a map that can disagree
        np.testing.assert_array_equal(predicted.numpy(), saved)
