"""Pipeline transforms for spike streams. Streams have T=129 channels: more
than OpenCV's 128-channel limit, so nothing may rely on OpenCV."""
import re

import numpy as np
import pytest
from mmcv.transforms import Compose

from mmseg.registry import TRANSFORMS
from wgse_mmseg.datasets import (LoadSpikeFromFile, SpikeRandomCrop,
                                 SpikeRandomFlip)
from wgse_mmseg.core.spike_formats import SpikeFileError
from wgse_mmseg.fileio.spike_files import load_spikes, save_spikes

T = 129


def _spikes(shape, seed=0):
    return (np.random.default_rng(seed).random(shape) < 0.3).astype(np.uint8)


def _positional(height, width, steps=T, seed=0):
    """An (H, W, T) image whose channels 0 and 1 hold the row and column,
    and a label map holding ``row * 1000 + col``."""
    img = _spikes((height, width, steps), seed)
    rows, cols = np.mgrid[:height, :width]
    img[..., 0] = rows
    img[..., 1] = cols
    gt = (rows * 1000 + cols).astype(np.int32)
    return img, gt


def _results(img, gt=None, path='data/spikes/sample.dat'):
    results = dict(img=img, img_path=path, img_shape=img.shape[:2],
                   ori_shape=img.shape[:2], seg_fields=[])
    if gt is not None:
        results['gt_seg_map'] = gt
        results['seg_map_path'] = 'data/labels/sample.png'
        results['seg_fields'] = ['gt_seg_map']
    return results


def test_registered():
    for name, cls in [('LoadSpikeFromFile', LoadSpikeFromFile),
                      ('SpikeRandomCrop', SpikeRandomCrop),
                      ('SpikeRandomFlip', SpikeRandomFlip)]:
        assert TRANSFORMS.get(name) is cls
    assert isinstance(
        TRANSFORMS.build(dict(type='SpikeRandomCrop', crop_size=(4, 4))),
        SpikeRandomCrop)


# ------------------------------------------------------- LoadSpikeFromFile
@pytest.fixture
def stream_file(tmp_path):
    spikes = _spikes((T, 6, 8), seed=1)
    path = str(tmp_path / 'stream.npy')
    save_spikes(path, spikes)
    return path, spikes


@pytest.mark.parametrize('num_steps', [1, 40, 41, 128, 129, None])
def test_load_centred_window(stream_file, num_steps):
    path, spikes = stream_file
    results = TRANSFORMS.build(
        dict(type='LoadSpikeFromFile', num_steps=num_steps))(dict(
            img_path=path))
    length = T if num_steps is None else num_steps
    start = T // 2 - length // 2  # 64 - length // 2
    expected = load_spikes(path, start=start, length=length)
    np.testing.assert_array_equal(expected, spikes[start:start + length])
    img = results['img']
    assert img.shape == (6, 8, length)
    assert img.dtype == np.uint8
    assert img.flags['C_CONTIGUOUS']
    np.testing.assert_array_equal(img, expected.transpose(1, 2, 0))
    assert tuple(results['img_shape']) == (6, 8)
    assert tuple(results['ori_shape']) == (6, 8)
    assert results['num_steps'] == length
    if num_steps == 41:
        # The annotated middle frame (64) is the window's centre frame.
        np.testing.assert_array_equal(img[..., 20], spikes[64])


@pytest.mark.parametrize('center, start', [(20, 0), (64, 44), (108, 88)])
def test_load_window_at_center(stream_file, center, start):
    path, spikes = stream_file
    results = LoadSpikeFromFile(num_steps=41, center=center)(dict(
        img_path=path))
    np.testing.assert_array_equal(results['img'],
                                  spikes[start:start + 41].transpose(1, 2, 0))


@pytest.mark.parametrize('center', [0, 19, 109, 128])
def test_a_window_past_the_stream_is_an_error_not_moved(stream_file, center):
    """One window policy (spike_formats.centered_window): a window that
    does not fit is refused with the centre frames that fit, never shifted
    away from the annotated frame."""
    path, _ = stream_file
    with pytest.raises(SpikeFileError, match=r'centre frames 20\.\.108 fit'):
        LoadSpikeFromFile(num_steps=41, center=center)(dict(img_path=path))


def test_load_dat_with_geometry(tmp_path):
    spikes = _spikes((T, 4, 6), seed=2)
    path = str(tmp_path / 'stream.dat')
    save_spikes(path, spikes)
    results = LoadSpikeFromFile(num_steps=41, height=4, width=6)(dict(
        img_path=path))
    np.testing.assert_array_equal(results['img'],
                                  spikes[44:85].transpose(1, 2, 0))


def test_load_too_few_frames_names_file(stream_file):
    path, _ = stream_file
    with pytest.raises(ValueError, match=re.escape(path)) as info:
        LoadSpikeFromFile(num_steps=T + 1)(dict(img_path=path))
    assert str(T) in str(info.value) and str(T + 1) in str(info.value)


def test_load_invalid_num_steps():
    with pytest.raises(ValueError):
        LoadSpikeFromFile(num_steps=0)


# --------------------------------------------------------- SpikeRandomCrop
@pytest.mark.parametrize('seed', range(5))
def test_crop_is_consistent(seed):
    np.random.seed(seed)
    img, gt = _positional(20, 30, seed=seed)
    results = SpikeRandomCrop(crop_size=(7, 11))(
        _results(img.copy(), gt.copy()))
    out, seg = results['img'], results['gt_seg_map']
    assert out.shape == (7, 11, T)
    assert seg.shape == (7, 11)
    assert tuple(results['img_shape']) == (7, 11)
    y0, x0 = int(out[0, 0, 0]), int(out[0, 0, 1])
    assert 0 <= y0 <= 20 - 7 and 0 <= x0 <= 30 - 11
    np.testing.assert_array_equal(out, img[y0:y0 + 7, x0:x0 + 11])
    np.testing.assert_array_equal(seg, gt[y0:y0 + 7, x0:x0 + 11])


def test_crop_larger_than_stream_keeps_it_whole():
    img, gt = _positional(5, 6)
    results = SpikeRandomCrop(crop_size=(8, 8))(_results(img.copy(),
                                                         gt.copy()))
    np.testing.assert_array_equal(results['img'], img)
    np.testing.assert_array_equal(results['gt_seg_map'], gt)


@pytest.mark.parametrize('patch_label', [2, 255], ids=['class', 'ignored'])
def test_crop_cat_max_ratio(patch_label):
    np.random.seed(0)
    img, _ = _positional(32, 32)
    label = np.ones((32, 32), np.uint8)
    label[10:14, 20:24] = patch_label
    position = _positional(32, 32)[1]
    transform = SpikeRandomCrop(crop_size=(8, 8), cat_max_ratio=0.75)
    for _ in range(5):
        results = _results(img.copy(), label.copy())
        results['pos_map'] = position.copy()
        results['seg_fields'] = ['gt_seg_map', 'pos_map']
        results = transform(results)
        out = results['img']
        assert out.shape == (8, 8, T)
        assert results['gt_seg_map'].shape == (8, 8)
        y0, x0 = int(out[0, 0, 0]), int(out[0, 0, 1])
        np.testing.assert_array_equal(out, img[y0:y0 + 8, x0:x0 + 8])
        np.testing.assert_array_equal(results['gt_seg_map'],
                                      label[y0:y0 + 8, x0:x0 + 8])
        np.testing.assert_array_equal(results['pos_map'],
                                      position[y0:y0 + 8, x0:x0 + 8])


def test_crop_prefers_mixed_crops():
    # Left half class 1, right half class 2: a crop with no class above 75%
    # exists (x0 in 11..13 of 0..24), and with 11 draws the transform finds
    # one far more often than a single draw (3/25) would.
    img, _ = _positional(8, 32)
    label = np.ones((8, 32), np.uint8)
    label[:, 16:] = 2
    transform = SpikeRandomCrop(crop_size=(8, 8), cat_max_ratio=0.75)
    np.random.seed(0)
    mixed = 0
    for _ in range(100):
        out = transform(_results(img.copy(), label.copy()))['gt_seg_map']
        counts = np.bincount(out.ravel(), minlength=3)
        mixed += counts.max() / counts.sum() < 0.75
    # P(found within 11 draws) = 1 - (22/25)**11 ~ 0.75
    assert 55 <= mixed <= 95


def test_crop_mismatched_label_names_file():
    img, gt = _positional(20, 30)
    with pytest.raises(ValueError, match='data/spikes/sample.dat'):
        SpikeRandomCrop(crop_size=(7, 11))(_results(img, gt[:, :29]))


# --------------------------------------------------------- SpikeRandomFlip
@pytest.mark.parametrize('direction, axes, name', [
    ('horizontal', (1, ), 'horizontal'),
    ('vertical', (0, ), 'vertical'),
    (('horizontal', 'vertical'), (0, 1), 'diagonal'),
    (['vertical', 'horizontal'], (0, 1), 'diagonal'),
])
def test_flip_prob_one(direction, axes, name):
    img, gt = _positional(9, 13)
    results = SpikeRandomFlip(prob=1.0, direction=direction)(
        _results(img.copy(), gt.copy()))
    np.testing.assert_array_equal(results['img'], np.flip(img, axis=axes))
    np.testing.assert_array_equal(results['gt_seg_map'],
                                  np.flip(gt, axis=axes))
    assert results['img'].shape == (9, 13, T)
    assert results['img'].flags['C_CONTIGUOUS']
    assert results['gt_seg_map'].flags['C_CONTIGUOUS']
    assert results['flip'] is True
    assert results['flip_direction'] == name


@pytest.mark.parametrize('direction', ['horizontal', 'vertical',
                                       ('horizontal', 'vertical')])
def test_flip_prob_zero(direction):
    img, gt = _positional(9, 13)
    results = SpikeRandomFlip(prob=0.0, direction=direction)(
        _results(img.copy(), gt.copy()))
    np.testing.assert_array_equal(results['img'], img)
    np.testing.assert_array_equal(results['gt_seg_map'], gt)
    assert results['flip'] is False
    assert results['flip_direction'] is None


@pytest.mark.parametrize('prob, axes, name', [
    ((1.0, 0.0), (1, ), 'horizontal'),
    ((0.0, 1.0), (0, ), 'vertical'),
])
def test_flip_per_direction_prob(prob, axes, name):
    img, gt = _positional(9, 13)
    results = SpikeRandomFlip(prob=prob)(_results(img.copy(), gt.copy()))
    np.testing.assert_array_equal(results['img'], np.flip(img, axis=axes))
    np.testing.assert_array_equal(results['gt_seg_map'],
                                  np.flip(gt, axis=axes))
    assert results['flip_direction'] == name


def test_flip_default_is_random_both_ways():
    img, gt = _positional(4, 5)
    transform = SpikeRandomFlip()
    np.random.seed(0)
    seen = {}
    for _ in range(200):
        results = transform(_results(img.copy(), gt.copy()))
        d = results['flip_direction']
        seen[d] = seen.get(d, 0) + 1
        axes = {None: (), 'horizontal': (1, ), 'vertical': (0, ),
                'diagonal': (0, 1)}[d]
        np.testing.assert_array_equal(results['img'], np.flip(img, axes))
        np.testing.assert_array_equal(results['gt_seg_map'],
                                      np.flip(gt, axes))
    assert set(seen) == {None, 'horizontal', 'vertical', 'diagonal'}
    assert all(20 <= n <= 80 for n in seen.values()), seen  # ~50 each


def test_flip_without_labels():
    img, _ = _positional(4, 5)
    results = SpikeRandomFlip(prob=1.0, direction='vertical')(_results(
        img.copy()))
    np.testing.assert_array_equal(results['img'], img[::-1])


@pytest.mark.parametrize('kwargs', [
    dict(direction='diagonal'), dict(direction='up'), dict(direction=[]),
    dict(direction=('horizontal', 'left')), dict(prob=1.5), dict(prob=-0.1),
    dict(prob=(0.5, 0.5, 0.5)), dict(prob=(0.5, 0.5), direction='vertical'),
])
def test_flip_invalid_arguments(kwargs):
    with pytest.raises(ValueError):
        SpikeRandomFlip(**kwargs)


def test_flip_mismatched_label_names_file():
    img, gt = _positional(9, 13)
    with pytest.raises(ValueError, match='data/spikes/sample.dat'):
        SpikeRandomFlip(prob=1.0)(_results(img, gt[:8]))


# ---------------------------------------------------------------- pipeline
def test_pipeline_load_crop_flip_pack(tmp_path):
    spikes = _spikes((T, 12, 16), seed=3)
    path = str(tmp_path / 'stream.spk')
    save_spikes(path, spikes)
    gt = np.arange(12 * 16, dtype=np.uint8).reshape(12, 16)
    # Built from MMSeg's registry (mmcv's Compose looks names up in mmcv's).
    pipeline = Compose([TRANSFORMS.build(cfg) for cfg in [
        dict(type='LoadSpikeFromFile', num_steps=T),
        dict(type='SpikeRandomCrop', crop_size=(8, 8)),
        dict(type='SpikeRandomFlip', prob=1.0, direction='horizontal'),
        dict(type='PackSegInputs'),
    ]])

    # Inject the label map after loading, as LoadAnnotations would.
    class _AddLabel:

        def __call__(self, results):
            results['gt_seg_map'] = gt.copy()
            results['seg_fields'] = ['gt_seg_map']
            return results

    pipeline.transforms.insert(1, _AddLabel())
    np.random.seed(0)
    packed = pipeline(dict(img_path=path))
    inputs = packed['inputs']
    assert tuple(inputs.shape) == (T, 8, 8)
    seg = packed['data_samples'].gt_sem_seg.data.numpy()[0]
    # Locate the crop from the (flipped) label values.
    flat = np.flip(seg, axis=1)
    y0, x0 = divmod(int(flat[0, 0]), 16)
    np.testing.assert_array_equal(flat, gt[y0:y0 + 8, x0:x0 + 8])
    expected = np.flip(spikes[:, y0:y0 + 8, x0:x0 + 8], axis=2)
    np.testing.assert_array_equal(inputs.numpy(), expected)
