"""The visualisation hook draws spike clips as TFP images, through the
visualiser's backends (here mmengine's local one)."""
import glob
import os.path as osp

import cv2
import numpy as np
from mmengine.registry import RUNNERS

import wgse_mmseg
from wgse_mmseg.core.exposure import apply_exposure
from wgse_mmseg.fileio.images import to_uint8
from wgse_mmseg.fileio.spike_files import load_spikes
from wgse_mmseg.core.reconstruction_baselines import tfp
from wgse_mmseg.utils.config import load_config

wgse_mmseg.register_all_modules()

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


def test_test_run_draws_the_clip_under_the_prediction(tiny_spike_dataset,
                                                      tmp_path):
    data = tiny_spike_dataset
    cfg = load_config(
        osp.join(ROOT, 'configs',
                 'segformer_b0_wgse.py'),
        {'data_root': str(data), 'num_steps': 9, 'crop_size': '32,64',
         'test_dataloader.num_workers': 0,
         'test_dataloader.persistent_workers': False,
         'default_hooks.visualization.draw': True,
         'default_hooks.visualization.interval': 1})
    cfg.work_dir = str(tmp_path / 'work')
    # a visualiser of its own: mmengine reuses one of the same name, with
    # the work dir of the test that made it
    cfg.visualizer.name = f'visualizer_{tmp_path.name}'
    cfg.visualizer.alpha = 0.0  # the drawing is the clip's image alone
    runner = RUNNERS.build(cfg)
    runner.test()
    drawn = glob.glob(str(tmp_path / 'work' / '*' / 'vis_data' /
                          'vis_image' / 'test_*.png'))
    assert len(drawn) == 1, drawn
    image = cv2.imread(drawn[0])[..., ::-1]
    # left half: the clip as an exposure-normalised TFP image (MMSeg's
    # visualiser puts the ground truth's overlay left of the prediction's;
    # with draw_gt both are blended over the same clip image)
    spike_file = glob.glob(str(data / 'spike' / 'val' / '**' / '*.spk'),
                           recursive=True)[0]
    expected = to_uint8(apply_exposure(tfp(load_spikes(spike_file))).image)
    assert image.shape[:2] == (32, 128)
    hook = [h for h in runner.hooks
            if type(h).__name__ == 'SpikeVisualizationHook'][0]
    clip = hook.clip_image(spike_file, 9)
    np.testing.assert_array_equal(clip[..., 0], expected)
    # ground truth's panel and the prediction's, each the clip's image
    np.testing.assert_array_equal(image[:, :64, 0], expected)
    np.testing.assert_array_equal(image[:, 64:, 0], expected)
