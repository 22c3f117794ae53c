"""SimulateSpikes: on-the-fly simulation in a data pipeline."""
import cv2
import numpy as np
import pytest
from mmcv.transforms import Compose

from mmseg.registry import TRANSFORMS
from wgse_mmseg.datasets.transforms.simulate import SimulateSpikes
from wgse_mmseg.core.simulation import simulate_spikes

pytestmark = pytest.mark.usefixtures('single_thread')


def _bgr(height=6, width=8, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3),
                                                dtype=np.uint8)


def test_registered_and_built_from_a_dict():
    transform = TRANSFORMS.build(
        dict(type='SimulateSpikes', num_steps=9, threshold=1 / 0.6,
             effects=dict(shot_noise={}), seed=0))
    assert isinstance(transform, SimulateSpikes)
    assert TRANSFORMS.get('SimulateSpikes') is SimulateSpikes
    assert 'num_steps=9' in repr(transform)


def test_output_like_load_spike_from_file():
    img = _bgr()
    results = SimulateSpikes(num_steps=17, seed=3)(dict(
        img=img.copy(), img_path='a/b.png'))
    spikes = results['img']
    assert spikes.shape == (6, 8, 17) and spikes.dtype == np.uint8
    assert spikes.flags['C_CONTIGUOUS']
    assert set(np.unique(spikes)) <= {0, 1}
    assert tuple(results['img_shape']) == tuple(results['ori_shape']) == (
        6, 8)
    assert results['num_steps'] == 17
    assert results['simulation']['effects'] == {}
    expected, _ = simulate_spikes(img[None, ..., ::-1], 17,
                                  seed=results['simulation']['seed'])
    np.testing.assert_array_equal(spikes, expected.transpose(1, 2, 0))


def test_channel_order():
    """A pure blue BGR image is blue (luma 0.114) read as BGR, red (0.299)
    read as RGB."""
    img = np.zeros((4, 4, 3), np.uint8)
    img[..., 0] = 255
    for order, luma in (('bgr', 0.114), ('rgb', 0.299)):
        rate = SimulateSpikes(num_steps=500, channel_order=order, seed=0)(
            dict(img=img.copy()))['img'].mean()
        assert abs(rate - luma) <= 1 / 500


def test_grey_frame():
    results = SimulateSpikes(num_steps=5, seed=0)(dict(
        img=np.full((3, 4), 255, np.uint8)))
    assert results['img'].shape == (3, 4, 5) and results['img'].all()


def test_seeded_samples_are_deterministic_and_distinct():
    img = _bgr(seed=1)
    transform = SimulateSpikes(num_steps=40, seed=5)

    def run(path):
        return transform(dict(img=img.copy(), img_path=path))['img']

    np.testing.assert_array_equal(run('x/1.png'), run('x/1.png'))
    assert not np.array_equal(run('x/1.png'), run('x/2.png'))
    other = SimulateSpikes(num_steps=40, seed=6)(dict(img=img.copy(),
                                                      img_path='x/1.png'))
    assert not np.array_equal(other['img'], run('x/1.png'))


def test_unseeded_streams_follow_numpy_global_seed():
    img = _bgr(seed=2)
    transform = SimulateSpikes(num_steps=40)
    np.random.seed(0)
    first = transform(dict(img=img.copy()))['img']
    second = transform(dict(img=img.copy()))['img']
    np.random.seed(0)
    replay = transform(dict(img=img.copy()))['img']
    assert not np.array_equal(first, second)
    np.testing.assert_array_equal(first, replay)


def test_sequence_from_frames_and_paths(tmp_path):
    frames = [_bgr(20, 24, seed=s) for s in range(3)]
    effects = dict(interpolation=dict(method='flow', preset='fast'))
    transform = SimulateSpikes(num_steps=12, effects=effects, seed=1)
    from_frames = transform(dict(frames=frames, img_path='seq'))
    assert from_frames['img'].shape == (20, 24, 12)
    assert from_frames['simulation']['resampling'] == 'flow'
    assert from_frames['simulation']['num_frames'] == 3
    paths = []
    for index, frame in enumerate(frames):
        paths.append(str(tmp_path / f'{index}.png'))
        cv2.imwrite(paths[-1], frame)
    from_paths = transform(dict(frame_paths=paths, img_path='seq'))
    np.testing.assert_array_equal(from_paths['img'], from_frames['img'])


@pytest.mark.parametrize('kwargs', [
    dict(num_steps=0), dict(num_steps=2.5), dict(num_steps=4, seed=-1),
    dict(num_steps=4, channel_order='bgra'),
    dict(num_steps=4, effects={'sparkle': {}}),
    dict(num_steps=4, effects={'jitter': {'std': -1}}),
])
def test_bad_arguments_fail_at_build(kwargs):
    with pytest.raises(ValueError):
        SimulateSpikes(**kwargs)


def test_bad_frames_name_the_sample():
    transform = SimulateSpikes(num_steps=4)
    with pytest.raises(ValueError, match='data/x.png'):  # float 0..255
        transform(dict(img=_bgr().astype(np.float32), img_path='data/x.png'))
    with pytest.raises(KeyError, match='frames'):
        transform(dict(img_path='data/x.png'))


def test_frames_of_different_sizes_are_refused_naming_them(tmp_path):
    transform = SimulateSpikes(num_steps=4)
    with pytest.raises(ValueError, match=r"results\['frames'\]\[1\] is "
                       r"shaped \(6, 9, 3\) but results\['frames'\]\[0\] "
                       r"\(8, 9, 3\)"):
        transform(dict(frames=[_bgr(8, 9), _bgr(6, 9)]))
    paths = [str(tmp_path / 'a.png'), str(tmp_path / 'b.png')]
    cv2.imwrite(paths[0], _bgr(8, 9))
    cv2.imwrite(paths[1], _bgr(8, 7))
    with pytest.raises(ValueError, match='b.png is shaped'):
        transform(dict(frame_paths=paths))


def test_pipeline_from_image_file_to_packed_inputs(tmp_path):
    image_path = str(tmp_path / 'frame.png')
    cv2.imwrite(image_path, _bgr(12, 16, seed=4))
    label_path = str(tmp_path / 'label.png')
    label = np.arange(12 * 16, dtype=np.uint8).reshape(12, 16) % 19
    cv2.imwrite(label_path, label)
    steps = 9
    pipeline = Compose([TRANSFORMS.build(cfg) for cfg in [
        dict(type='LoadImageFromFile'),
        dict(type='LoadAnnotations'),
        dict(type='SimulateSpikes', num_steps=steps, threshold=1 / 0.6,
             effects=dict(camera_motion=dict(translation=[1.0, 0.0],
                                             per='clip')), seed=0),
        dict(type='SpikeRandomCrop', crop_size=(8, 8)),
        dict(type='SpikeRandomFlip', prob=1.0, direction='horizontal'),
        dict(type='PackSegInputs'),
    ]])
    np.random.seed(0)
    packed = pipeline(dict(img_path=image_path, seg_map_path=label_path,
                           reduce_zero_label=False, seg_fields=[]))
    assert tuple(packed['inputs'].shape) == (steps, 8, 8)
    assert set(packed['inputs'].unique().tolist()) <= {0, 1}
    seg = packed['data_samples'].gt_sem_seg.data.numpy()[0]
    assert seg.shape == (8, 8)


def test_scene_file_is_read_once(tmp_path):
    path = tmp_path / 'scene.yaml'
    path.write_text('shot_noise: {electrons: 100}\n')
    transform = SimulateSpikes(num_steps=6, effects=str(path), seed=0)
    path.unlink()  # read at build time
    results = transform(dict(img=_bgr()))
    assert results['simulation']['effects'] == {
        'shot_noise': {'electrons': 100, 'exact_below': 1000.0}}
