"""Bad input at the public entry points: a clear error that names the
parameter or the file and what was expected, never an exception from deep
inside numpy, torch, OpenCV or mmengine (readers' random bytes and
truncations: tests/fileio/test_spike_files.py; converters and tools: their
tests)."""
import re

import numpy as np
import pytest
import torch
from mmengine.structures import PixelData

import wgse_mmseg
from mmseg.registry import DATASETS, MODELS, TRANSFORMS
from mmseg.structures import SegDataSample
from wgse_mmseg.core import TFI, TFP, WGSE, simulate_spikes
from wgse_mmseg.core.spike_formats import SpikeFileError

wgse_mmseg.register_all_modules()

FRAMES = np.full((2, 6, 8), 0.5)


def _raises(match, call, error=ValueError):
    with pytest.raises(error, match=match) as info:
        call()
    # raised by this package, not from inside a dependency
    assert 'wgse_mmseg' in info.traceback[-1].path.as_posix(), info


@pytest.mark.parametrize('kwargs, match', [
    (dict(level=0), 'level must be an integer >= 1'),
    (dict(level=1.5), 'level must be an integer >= 1'),
    (dict(level=True), 'level must be an integer >= 1'),
    (dict(hidden_channels=0), 'hidden_channels must be an integer >= 1'),
    (dict(hidden_channels=-3), 'hidden_channels must be an integer >= 1'),
    (dict(hidden_channels=2.5), 'hidden_channels must be an integer >= 1'),
    (dict(num_blocks=0), 'num_blocks must be an integer >= 1'),
    (dict(kernel_size=2), 'kernel_size must be an odd integer >= 1'),
    (dict(kernel_size=True), 'kernel_size must be an odd integer'),
    (dict(wavelet='nope'), 'wavelet must be a discrete PyWavelets'),
    (dict(mode='bogus'), 'mode must be one of'),
    (dict(dim=4), r'dim must be one of \[1, 2, 3\]'),
    (dict(backend='x'), 'backend must be one of'),
])
def test_wgse_arguments(kwargs, match):
    _raises(match, lambda: WGSE(**kwargs))


@pytest.mark.parametrize('spikes, match', [
    (torch.zeros(9, 4, 4), r'shaped \(B, T, H, W\)'),
    (torch.zeros(1, 1, 9, 4, 4), r'shaped \(B, T, H, W\)'),
    (torch.zeros(1, 0, 4, 4),
     r"WGSE: the spikes' time dimension T \(B, T, H, W\) must be at least 1"),
])
def test_wgse_inputs(spikes, match):
    _raises(match, lambda: WGSE()(spikes))


@pytest.mark.parametrize('module', [TFP(window=5), TFI()])
@pytest.mark.parametrize('spikes', [torch.zeros(9, 4, 4),
                                    torch.zeros(1, 0, 4, 4)])
def test_representation_inputs(module, spikes):
    _raises(r'expects spikes shaped \(B, T, H, W\)', lambda: module(spikes))


@pytest.mark.parametrize('value, match', [
    (float('nan'), 'TFI: spikes holds 36 non-finite value'),
    (float('inf'), 'TFI: spikes holds 36 non-finite value'),
    (-1.0, 'TFI expects binary spikes'), (5.0, 'TFI expects binary spikes')])
def test_tfi_refuses_what_cannot_be_spikes(value, match):
    _raises(match, lambda: TFI()(torch.full((1, 9, 2, 2), value)))


@pytest.mark.parametrize('args, kwargs, match', [
    ((FRAMES, 0), {}, 'num_steps must be an integer >= 1'),
    ((FRAMES, 2.5), {}, 'num_steps must be an integer >= 1'),
    ((np.full((2, 6, 8), np.nan), 9), {}, r'must lie in \[0, 1\]'),
    ((np.full((2, 6, 8), np.inf), 9), {}, r'must lie in \[0, 1\]'),
    ((-FRAMES, 9), {}, r'must lie in \[0, 1\]'),
    ((np.zeros((0, 6, 8)), 9), {}, 'non-empty'),
    ((np.zeros(5), 9), {}, 'non-empty'),
    ((np.full((2, 6, 8), 300, np.int32), 9), {}, 'bool, uint8 .* or float'),
    ((FRAMES, 9), dict(threshold=0), 'threshold must be a finite number'),
    ((FRAMES, 9), dict(threshold=float('nan')), 'threshold must be'),
    ((FRAMES, 9), dict(seed=-1),
     'seed must be an integer >= 0 and <= 9223372036854775807'),
    ((FRAMES, 9), dict(seed=2**80), 'seed must be an integer >= 0'),
    ((FRAMES, 9), dict(seed=1.5), 'seed must be an integer'),
    ((FRAMES, 9), dict(effects={'nope': {}}), r"unknown effect\(s\)"),
    ((FRAMES, 9), dict(effects={'shot_noise': {'bogus': 1}}),
     r'shot_noise: unknown parameter\(s\)'),
])
def test_simulator_inputs(args, kwargs, match):
    _raises(match, lambda: simulate_spikes(*args, **kwargs))


def _preprocessor(**kwargs):
    return MODELS.build(dict(dict(type='SpikeSegDataPreProcessor',
                                  num_steps=9, num_classes=19, size=(4, 4)),
                             **kwargs))


@pytest.mark.parametrize('kwargs, match', [
    (dict(num_steps=0), 'num_steps must be an integer >= 1'),
    (dict(num_steps=4.5), 'num_steps must be an integer >= 1'),
    (dict(num_classes=0), 'num_classes must be an integer >= 1'),
    (dict(size=(0, 4)), r'size must be \(h, w\)'),
    (dict(size=(-4, 4)), r'size must be \(h, w\)'),
    (dict(size=(4, )), r'size must be \(h, w\)'),
    (dict(pad_val=2), 'pad_val must be one of'),
    (dict(pad_val=float('nan')), 'pad_val must be one of'),
    (dict(seg_pad_val=300), 'seg_pad_val must be an integer >= 0 and <= 255'),
])
def test_preprocessor_arguments(kwargs, match):
    _raises(match, lambda: _preprocessor(**kwargs))


def _batch(spikes, labels=None):
    sample = SegDataSample()
    sample.set_metainfo(dict(img_shape=spikes.shape[-2:],
                             ori_shape=spikes.shape[-2:],
                             img_path='clip.spk', seg_map_path='label.png'))
    if labels is not None:
        sample.gt_sem_seg = PixelData(data=labels)
    return dict(inputs=[spikes], data_samples=[sample])


@pytest.mark.parametrize('spikes, match', [
    (torch.full((9, 4, 4), float('nan')), 'clip.spk: a spike stream holds '
                                          'only 0 and 1'),
    (torch.rand(9, 4, 4) + 0.01, 'clip.spk: a spike stream holds only'),
    (3 * torch.ones(9, 4, 4, dtype=torch.uint8), r'found \[3\]'),
    (-torch.ones(9, 4, 4), r'found \[-1.0\]'),
    (torch.zeros(5, 4, 4), 'clip.spk: spike stream has T=5'),
    (torch.zeros(4, 4), r'clip.spk: spike stream has shape \(4, 4\)'),
    (torch.zeros(9, 0, 4), 'clip.spk: empty spike stream'),
])
def test_preprocessor_inputs(spikes, match):
    _raises(match, lambda: _preprocessor()(_batch(spikes), True))


@pytest.mark.parametrize('labels, match', [
    (torch.full((1, 4, 4), 19, dtype=torch.uint8), r'label.png: label '
                                                   r'values \[19\]'),
    (torch.full((1, 4, 4), -1), r'label values \[-1\]'),
    (torch.full((1, 4, 4), 0.5), r'label values \[0.5\]'),
    (torch.zeros((1, 3, 3), dtype=torch.uint8), r'label.png: label map is '
                                                r'\(3, 3\)'),
])
def test_preprocessor_labels(labels, match):
    spikes = torch.zeros(9, 4, 4, dtype=torch.uint8)
    _raises(match, lambda: _preprocessor()(_batch(spikes, labels), True))


def test_all_good_binary_dtypes_pass():
    for dtype in (torch.uint8, torch.bool, torch.int64, torch.float32):
        out = _preprocessor()(_batch(torch.ones(9, 4, 4, dtype=dtype)), True)
        assert out['inputs'].shape == (1, 9, 4, 4)


@pytest.mark.parametrize('cfg, match', [
    (dict(type='LoadSpikeFromFile', num_steps=0), 'num_steps must be an'),
    (dict(type='LoadSpikeFromFile', num_steps=2.5), 'num_steps must be an'),
    (dict(type='LoadSpikeFromFile', height=-2, width=4), 'height must be'),
    (dict(type='LoadSpikeFromFile', center=-1),
     'center must be an integer >= 0'),
    (dict(type='SpikeRandomCrop', crop_size=(0, 4)), r'crop_size must be'),
    (dict(type='SpikeRandomCrop', crop_size=(-1, 4)), r'crop_size must be'),
    (dict(type='SpikeRandomCrop', crop_size=(4, 4), cat_max_ratio=-1),
     'cat_max_ratio must be a finite number > 0 and <= 1'),
    (dict(type='SpikeRandomFlip', prob=2),
     r'prob must be a probability in \[0, 1\]'),
    (dict(type='SpikeRandomFlip', direction='diagonal'), 'direction must'),
    (dict(type='SimulateSpikes', num_steps=0), 'num_steps must be an'),
    (dict(type='LoadSpikeImagePair', num_steps=0), 'num_steps must be an'),
    (dict(type='LoadSpikeImagePair', num_steps=2.5), 'num_steps must be'),
    (dict(type='LoadSpikeImagePair', height=-1, width=3), 'height must be'),
])
def test_transform_arguments(cfg, match):
    _raises(match, lambda: TRANSFORMS.build(cfg))


@pytest.mark.parametrize('path, match', [
    ('/nonexistent/clip.spk', 'no such spike file'),
    ('/tmp', "unknown spike file extension ''"),
])
def test_loading_names_the_file(path, match):
    load = TRANSFORMS.build(dict(type='LoadSpikeFromFile', num_steps=9))
    _raises(match, lambda: load(dict(img_path=path)), SpikeFileError)


def test_loading_a_text_file_names_it(tmp_path):
    path = tmp_path / 'notes.spk'
    path.write_text('hello')
    load = TRANSFORMS.build(dict(type='LoadSpikeFromFile', num_steps=9))
    _raises(f'{path}: 5 bytes is shorter than the 32-byte .spk header',
            lambda: load(dict(img_path=str(path))), SpikeFileError)


def test_a_missing_dataset_root_is_named(tmp_path):
    _raises(f'{tmp_path}/spike/train .* is not a directory', lambda:
            DATASETS.build(dict(
                type='SpikeCityscapesDataset', data_root=str(tmp_path),
                data_prefix=dict(img_path='spike/train',
                                 seg_map_path='gtFine/train'),
                pipeline=[])), FileNotFoundError)


@pytest.mark.parametrize('kwargs, name', [
    (dict(num_samples=0), 'num_samples'), (dict(num_samples=2.5),
                                           'num_samples'),
    (dict(crop_size=(0, 4)), 'crop_size'), (dict(crop_size=(4, )),
                                            'crop_size'),
    (dict(num_steps=0), 'num_steps'), (dict(seed=-1), 'seed'),
    (dict(white_rate=0), 'white_rate'),
    (dict(white_rate=float('nan')), 'white_rate'),
    (dict(gain_range=(1, 0)), 'gain_range'),
    (dict(gamma_range=(0, 1)), 'gamma_range'),
    (dict(scale_range=(1, float('inf'))), 'scale_range'),
    (dict(max_speed=-1), 'max_speed'), (dict(max_side=0), 'max_side'),
])
def test_simulated_image_dataset_arguments(kwargs, name):
    _raises(f'SimulatedSpikeImageDataset: {name} must be', lambda:
            DATASETS.build(dict(type='SimulatedSpikeImageDataset',
                                pipeline=[], **kwargs)))


# ---------------- input the package accepted never fails inside a library
def test_a_batch_of_mixed_t_is_refused_naming_the_sample():
    first, second = _batch(torch.zeros(9, 4, 4)), _batch(torch.zeros(7, 4,
                                                                     4))
    second['data_samples'][0].set_metainfo(dict(img_path='other.spk'))
    batch = dict(inputs=first['inputs'] + second['inputs'],
                 data_samples=first['data_samples'] +
                 second['data_samples'])
    preprocessor = _preprocessor(num_steps=None, size=(4, 4))
    _raises(r'other.spk: spike stream shaped \(7, 4, 4\) in a batch whose '
            r'first, clip.spk, is \(9, 4, 4\)',
            lambda: preprocessor(batch, True))


def test_a_crop_weighed_by_labels_without_labels_is_refused():
    crop = TRANSFORMS.build(dict(type='SpikeRandomCrop', crop_size=4,
                                 cat_max_ratio=0.75))
    results = dict(img=np.zeros((8, 8, 9), np.uint8), img_path='clip.spk',
                   seg_fields=[])
    _raises('SpikeRandomCrop: cat_max_ratio=0.75 .* clip.spk has none',
            lambda: crop(results))
    TRANSFORMS.build(dict(type='SpikeRandomCrop', crop_size=4))(results)


def test_output_norm_refuses_a_one_value_training_batch():
    model = WGSE(output_norm=True, wavelet=None).train()
    _raises('output_norm=True.* at least 2 values',
            lambda: model(torch.zeros(1, 1, 1, 1)))
    assert model(torch.zeros(1, 1, 1, 2)).shape == (1, 1, 1, 2)
    model.eval()(torch.zeros(1, 1, 1, 1))  # running statistics: fine


@pytest.mark.parametrize('text, match', [
    ('a = {[1]: 2}', "dict key '\\[1\\]' is a list"),
    ('a = {([1], 2): 2}', 'is a tuple, which cannot be a key'),
    ('a = dict(b={{}: 1})', 'is a dict, which cannot be a key'),
    ('a = ' + '[' * 40 + ']' * 40, 'nested deeper than 32 levels'),
    ('a = ' + '(' * 5000 + ')' * 5000, 'ckpt.pth'),
    ('a = "' + 'x' * (2 ** 20) + '"', 'characters; at most'),
])
def test_config_text_from_a_checkpoint_that_is_no_config(text, match):
    from wgse_mmseg.utils.config_data import ConfigDataError, read_config_data
    _raises(match, lambda: read_config_data(text, "ckpt.pth: meta['cfg']"),
            ConfigDataError)


def test_a_refused_checkpoint_never_advises_turning_safety_off(tmp_path):
    import pickle
    from wgse_mmseg.utils.checkpoint import CheckpointError, read_checkpoint

    class Code:
        def __reduce__(self):
            return (print, ('ran',))

    path = tmp_path / 'evil.pth'
    path.write_bytes(pickle.dumps({'state_dict': Code()}, protocol=2))
    with pytest.raises(CheckpointError) as info:
        read_checkpoint(str(path))
    message = str(info.value)
    assert str(path) in message and 'weights_only' not in message
    assert 'trusted' not in message and 'safe_globals' not in message


@pytest.mark.parametrize('code, strerror', [
    (28, 'No space left on device'), (30, 'Read-only file system')])
def test_a_write_that_fails_names_its_file(tmp_path, code, strerror):
    from wgse_mmseg.fileio.atomic import atomic_output
    target = tmp_path / 'out.bin'
    with pytest.raises(OSError) as info:
        with atomic_output(str(target)) as f:
            f.write(b'partial')
            raise OSError(code, strerror)
    assert info.value.errno == code
    assert f'{target}: cannot be written: {strerror}' in str(info.value)
    assert list(tmp_path.iterdir()) == []  # nothing half-written


def test_onnx_errors_name_the_model(tmp_path):
    import os
    from wgse_mmseg.apis.onnx_segmentor import OnnxSpikeSegmentor
    odd = os.path.join(os.fsencode(str(tmp_path)), b'model\xff.onnx')
    with open(odd, 'wb') as f:
        f.write(b'not read')
    _raises('model.*: the path holds bytes that are not UTF-8',
            lambda: OnnxSpikeSegmentor(os.fsdecode(odd)))

    class Session:
        def run(self, outputs, feed):
            raise RuntimeError('[ONNXRuntimeError] : 2 : INVALID_ARGUMENT : '
                               'Non-zero status code returned while running '
                               'Reshape node')

    model = OnnxSpikeSegmentor.__new__(OnnxSpikeSegmentor)
    model.session, model.path = Session(), 'foreign.onnx'
    _raises(r'foreign.onnx: the model failed inside its graph on input '
            r'\(1, 9, 4, 4\) \(RuntimeError: \[ONNXRuntimeError\]',
            lambda: model._graph(np.zeros((1, 9, 4, 4), np.float32)))


def test_an_input_below_the_models_smallest_is_refused_before_inference():
    import os.path as osp
    from mmengine.registry import init_default_scope
    from wgse_mmseg.utils.config import load_config
    from wgse_mmseg.utils.cross_checks import ModelFitError, check_input_fits
    root = osp.dirname(osp.dirname(osp.abspath(__file__)))
    cfg = load_config(osp.join(root, 'configs', 'segformer_b0_wgse.py'),
                      dict(num_steps=9))
    init_default_scope('mmseg')
    model = MODELS.build(cfg.model).eval()
    with pytest.raises(ModelFitError, match=r'rec.npy: frames of 8x12 are '
                       r'below the smallest input the model takes, '
                       r'(\d+)x\1') as info:
        check_input_fits(model, 9, 8, 12, 'rec.npy')
    side = int(re.search(r'takes, (\d+)x', str(info.value)).group(1))
    check_input_fits(model, 9, side, side, 'rec.npy')  # the smallest runs
    with pytest.raises(ModelFitError):  # and one less does not
        check_input_fits(model, 9, side - 1, side, 'rec.npy')


def test_an_export_shape_below_the_models_smallest_names_the_shape(
        tmp_path):
    import os.path as osp
    from mmengine.registry import init_default_scope
    from wgse_mmseg.apis.onnx_export import SpikeSegmentorGraph, export_onnx
    from wgse_mmseg.utils.config import load_config
    root = osp.dirname(osp.dirname(osp.abspath(__file__)))
    cfg = load_config(osp.join(root, 'configs', 'segformer_b0_wgse.py'),
                      dict(num_steps=9))
    init_default_scope('mmseg')
    graph = SpikeSegmentorGraph(MODELS.build(cfg.model))
    out = tmp_path / 'm.onnx'
    _raises(f'{out} \\(the export shape\\): frames of 8x12 are below the '
            f'smallest input the model takes',
            lambda: export_onnx(graph, str(out), 9, 8, 12))
    assert not out.exists()
