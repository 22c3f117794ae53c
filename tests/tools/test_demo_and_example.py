"""The worked example config (DeepLabV3+-R18 + WGSE) and tools/demo.py."""
import csv
import json
import os.path as osp
import subprocess
import sys
import types

import cv2
import numpy as np
import pytest
import torch
from PIL import Image

import wgse_mmseg
from mmengine.registry import init_default_scope
from mmengine.structures import PixelData
from mmseg.registry import MODELS
from mmseg.structures import SegDataSample
from wgse_mmseg.utils.config import load_config
from wgse_mmseg.datasets import SpikeCityscapesDataset
from wgse_mmseg.fileio.spike_files import load_spikes, save_spikes

wgse_mmseg.register_all_modules()  # before mmseg builds anything

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
EXAMPLE = osp.join(ROOT, 'configs', 'examples', 'deeplabv3plus_r18_wgse.py')
DEMO = osp.join(ROOT, 'tools', 'demo.py')
NUM_STEPS = 9  # small T keeps WGSE fast on CPU
CROP = (32, 64)
WGSE_PARAMS = 19974  # 6 bands (db8, level 5) x 3329 parameters each


def _build(**options):
    cfg = load_config(EXAMPLE, dict(num_steps=NUM_STEPS, crop_size=CROP,
                                    **options))
    init_default_scope(cfg.get('default_scope', 'mmseg'))
    return cfg, MODELS.build(cfg.model)


def _count(model):
    return sum(p.numel() for p in model.parameters())


def _spikes(steps, height, width, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.random((steps, height, width)) < 0.2).astype(np.uint8)


def test_example_config_trains_on_spikes():
    torch.manual_seed(0)
    cfg, model = _build()
    assert cfg.model.backbone.in_channels == NUM_STEPS
    assert model.data_preprocessor.num_steps == NUM_STEPS
    assert type(model.data_preprocessor).__name__ == \
        'SpikeSegDataPreProcessor'
    assert type(model.data_preprocessor.enhancer).__name__ == 'WGSE'

    inputs, samples = [], []
    for index in range(2):
        inputs.append(torch.from_numpy(_spikes(NUM_STEPS, *CROP, index)))
        sample = SegDataSample()
        sample.gt_sem_seg = PixelData(data=torch.randint(0, 19, (1, *CROP)))
        sample.set_metainfo(dict(img_shape=CROP, ori_shape=CROP))
        samples.append(sample)
    model.train()
    data = model.data_preprocessor(dict(inputs=inputs, data_samples=samples),
                                   True)
    assert data['inputs'].shape == (2, NUM_STEPS, *CROP)
    losses = model.loss(data['inputs'], data['data_samples'])
    loss = sum(v for k, v in losses.items() if 'loss' in k)
    assert torch.isfinite(loss)
    loss.backward()
    for name, param in model.named_parameters():
        if name.startswith(('data_preprocessor.enhancer', 'backbone.stem')):
            assert param.grad is not None, name

    _, plain = _build(**{'model.data_preprocessor.enhancer': None})
    assert plain.data_preprocessor.enhancer is None
    assert _count(model) - _count(plain) == WGSE_PARAMS


@pytest.fixture(scope='module')
def checkpoint(tmp_path_factory):
    """An untrained example model saved as a checkpoint for T=NUM_STEPS."""
    torch.manual_seed(0)
    _, model = _build()
    path = tmp_path_factory.mktemp('ckpt') / 'model.pth'
    meta = dict(classes=SpikeCityscapesDataset.METAINFO['classes'],
                palette=SpikeCityscapesDataset.METAINFO['palette'])
    torch.save({'state_dict': model.state_dict(),
                'meta': {'dataset_meta': meta}}, path)
    return path


def _demo(*args, cwd):
    return subprocess.run(
        [sys.executable, DEMO, *map(str, args), '--device', 'cpu',
         '--cfg-options', f'num_steps={NUM_STEPS}'],
        cwd=cwd, capture_output=True, text=True, timeout=300)


def test_demo_writes_overlay(tmp_path, checkpoint):
    height, width = 24, 40  # not the crop size: inference is on whole frames
    spike_file = tmp_path / 'stream.spk'
    save_spikes(str(spike_file), _spikes(NUM_STEPS + 6, height, width))
    out = tmp_path / 'out' / 'overlay.png'
    proc = _demo(spike_file, EXAMPLE, checkpoint, '--out-file', out,
                 cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert str(out) in proc.stdout
    image = cv2.imread(str(out))
    assert image is not None and image.shape == (height, width, 3)
    assert not list((tmp_path / 'out').glob('.tmp-*'))  # no temp left over


def test_demo_rejects_short_stream(tmp_path, checkpoint):
    spike_file = tmp_path / 'short.spk'
    save_spikes(str(spike_file), _spikes(NUM_STEPS - 4, 16, 16))
    proc = _demo(spike_file, EXAMPLE, checkpoint, cwd=tmp_path)
    assert proc.returncode != 0
    assert str(spike_file) in proc.stderr
    assert f'T={NUM_STEPS - 4}' in proc.stderr
    assert f'num_steps={NUM_STEPS}' in proc.stderr
    assert 'Traceback' not in proc.stderr
    assert not (tmp_path / 'short_seg.png').exists()


def test_demo_grey_image_and_blend(load_tool):
    demo = load_tool('tools/demo.py')

    spikes = torch.zeros(10, 2, 3, dtype=torch.uint8)
    spikes[:3, 0, 0] = 1  # rate 0.3: TFP 0.5
    spikes[:1, 1, 2] = 1  # rate 0.1: TFP 1/6
    grey, exposed = demo.clip_image(spikes, 'none')
    assert grey.dtype == np.uint8 and exposed.gain == 1.0
    assert grey[0, 0] == 128 and grey[1, 2] == 42 and grey[0, 1] == 0
    # auto: a clip of normal brightness (bright end near 0.5) is untouched
    auto, exposed = demo.clip_image(spikes, 'auto')
    assert exposed.gain == 1.0 and 'left as it is' in exposed.reason
    np.testing.assert_array_equal(auto, grey)
    # a dark one (rate 0.1 at most: TFP 1/6): its 99.5th percentile (by
    # numpy's linear interpolation over 6 pixels) becomes white
    spikes[1:3, 0, 0] = 0
    dark = np.percentile([1 / 6, 1 / 6, 0, 0, 0, 0], 99.5)
    grey, exposed = demo.clip_image(spikes, 'auto')
    assert exposed.gain == pytest.approx(1 / dark)
    assert 'under-exposed' in exposed.reason
    assert grey[0, 0] == 255 and grey[1, 2] == 255 and grey[0, 1] == 0
    black, exposed = demo.clip_image(torch.zeros(4, 2, 3, dtype=torch.uint8),
                                     'auto')
    assert black.max() == 0 and exposed.gain == 1.0

    labels = np.zeros((2, 3), np.int64)
    palette = [[200, 100, 0]]
    assert (demo.overlay(grey, labels, palette, 0.0) == grey[...,
                                                             None]).all()
    assert (demo.overlay(grey, labels, palette, 1.0) == palette[0]).all()


@pytest.fixture(scope='module')
def varied_checkpoint(tmp_path_factory):
    """The untrained example model with its classifier's weights drawn
    from N(0, 1) and no bias: it predicts 7-9 classes a window (the
    untrained one, one class everywhere, would hide a wrong label)."""
    torch.manual_seed(0)
    _, model = _build()
    with torch.no_grad():
        model.decode_head.conv_seg.weight.normal_(0, 1)
        model.decode_head.conv_seg.bias.zero_()
    path = tmp_path_factory.mktemp('ckpt') / 'varied.pth'
    torch.save({'state_dict': model.state_dict()}, path)
    return path


def _dat_recording(path, steps, height, width, seed=0):
    """A random ``.dat`` recording with its side file."""
    save_spikes(str(path), _spikes(steps, height, width, seed))
    (path.parent / (path.name + '.json')).write_text(
        json.dumps(dict(height=height, width=width)))
    return path


def test_demo_walk_segments_each_window_as_the_one_window_demo(
        tmp_path, varied_checkpoint, load_tool):
    """The walk as a user runs it; the one-window demo (the same ``main``,
    in this process) on a window alone gives the walk's frame of it."""
    checkpoint = varied_checkpoint
    recording = _dat_recording(tmp_path / 'rec.dat', 300, 24, 40)
    out = tmp_path / 'walk' / 'rec.gif'
    proc = _demo(recording, EXAMPLE, checkpoint, '--stride', '25',
                 '--batch-size', '3', '--out-file', out, '--save-frames',
                 cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    # T=9: centre 0's window starts at -4 (skipped); 275's ends at 280
    centres = list(range(25, 276, 25))
    assert '11 windows of 9 readouts centred on readouts 25..275' in \
        proc.stdout and 'at the start 0, at the end none' in proc.stdout
    assert 'window/s' in proc.stderr  # the progress bar
    with open(tmp_path / 'walk' / 'rec.csv') as f:
        rows = list(csv.DictReader(f))
    assert [int(r['centre']) for r in rows] == centres
    assert [int(r['batch']) for r in rows] == [i // 3 * 3
                                               for i in range(11)]
    with Image.open(out) as gif:
        assert gif.n_frames == 11 and gif.size == (40, 24)
    frames = tmp_path / 'walk' / 'rec_frames'
    assert len(list(frames.glob('*.png'))) == 11
    # the one-window demo on the window alone gives the walk's frame
    demo = load_tool('tools/demo.py')
    for index in (0, 10):
        centre = centres[index]
        alone = tmp_path / f'alone{centre}.spk'
        save_spikes(str(alone), load_spikes(str(recording),
                                            start=centre - NUM_STEPS // 2,
                                            length=NUM_STEPS))
        png = tmp_path / f'alone{centre}.png'
        demo.main([str(alone), EXAMPLE, str(checkpoint), '--out-file',
                   str(png), '--device', 'cpu', '--cfg-options',
                   f'num_steps={NUM_STEPS}'])
        np.testing.assert_array_equal(
            cv2.imread(str(frames / f'{index:06d}.png')),
            cv2.imread(str(png)))


class FakeOnnxSegmentor:
    """``OnnxSpikeSegmentor``'s contract: ``(B, T, H, W)`` float spikes ->
    ``(B, K, H, W)`` logits; class 1 where the spike rate exceeds 0.2;
    exported for ``input_shape`` ``(T, H, W)``."""
    made = []
    input_shape = (NUM_STEPS, 16, 24)

    def __init__(self, onnx_path, device='cpu'):
        self.made.append((onnx_path, device))

    def __call__(self, spikes):
        rate = spikes.mean(1)
        return torch.stack([torch.full_like(rate, 0.2), rate], 1)


def test_demo_onnxruntime_backend_runs_the_exported_model(
        tmp_path, checkpoint, monkeypatch, load_tool):
    """The plumbing of --backend onnxruntime, with a stand-in for the
    exported model (the class is imported only when asked)."""
    fake = types.ModuleType('wgse_mmseg.apis.onnx_segmentor')
    fake.OnnxSpikeSegmentor = FakeOnnxSegmentor
    monkeypatch.setitem(sys.modules, 'wgse_mmseg.apis.onnx_segmentor', fake)
    demo = load_tool('tools/demo.py')
    recording = _dat_recording(tmp_path / 'rec.dat', 60, 16, 24)
    onnx = tmp_path / 'model.onnx'
    onnx.write_bytes(b'stand-in')
    video = tmp_path / 'rec.mp4'
    common = ['--device', 'cpu', '--backend', 'onnxruntime', '--opacity',
              '0.7', '--cfg-options', f'num_steps={NUM_STEPS}']
    demo.main([str(recording), EXAMPLE, str(onnx), '--stride', '10',
               '--out-file', str(video), '--save-frames', *common])
    assert FakeOnnxSegmentor.made[-1] == (str(onnx), 'cpu')
    palette = SpikeCityscapesDataset.METAINFO['palette']

    def expected(window):
        labels = (window.mean(0) > 0.2).astype(np.int64)
        grey, _ = demo.clip_image(torch.from_numpy(window), 'auto')
        return demo.overlay(grey, labels, palette, 0.7)[..., ::-1]
    centres = range(10, 51, 10)
    for index, centre in enumerate(centres):
        window = load_spikes(str(recording), start=centre - 4, length=9)
        np.testing.assert_array_equal(
            cv2.imread(str(tmp_path / 'rec_frames' / f'{index:06d}.png')),
            expected(window))
    # and one window, as the demo without --stride
    png = tmp_path / 'one.png'
    demo.main([str(recording), EXAMPLE, str(onnx), '--out-file', str(png),
               *common])
    np.testing.assert_array_equal(cv2.imread(str(png)), expected(
        load_spikes(str(recording), start=30 - 4, length=9)))
