"""Models and metadata read from files, checked against the interface they
must have before use (issue 32, item 2): ONNX files given to
``OnnxSpikeSegmentor``, checkpoint metadata, JSON from files.

The ONNX models here are built by hand (a few operators), each declaring
one interface; the reference of the logits is NumPy on the same spikes.
"""
import json

import numpy as np
import onnx
import pytest
import torch
from hypothesis import given, settings, strategies as st
from onnx import TensorProto, helper

from wgse_mmseg.apis.onnx_segmentor import OnnxSpikeSegmentor
from wgse_mmseg.apis.segmentor_checkpoint import load_segmentor
from wgse_mmseg.fileio.bounded_reads import (json_depth, load_json_file,
                                             parse_json)
from wgse_mmseg.limits import MAX_JSON_DEPTH
from wgse_mmseg.utils.checkpoint import CheckpointError, check_dataset_meta

T, H, W = 3, 4, 5


def _model(path, in_type=TensorProto.FLOAT, in_shape=('n', T, H, W),
           out_type=None, out_shape=('n', 2, H, W), names=('spikes', 'logits'),
           meta=None, nodes=None):
    """logits = (mean over T, -mean over T) of the spikes, ``(B, 2, H, W)``,
    in the input's element type unless ``nodes`` say otherwise."""
    out_type = in_type if out_type is None else out_type
    x = helper.make_tensor_value_info(names[0], in_type, list(in_shape))
    y = helper.make_tensor_value_info(names[1], out_type, list(out_shape))
    nodes = nodes or [
        helper.make_node('ReduceMean', [names[0]], ['m'], axes=[1],
                         keepdims=1),
        helper.make_node('Neg', ['m'], ['n']),
        helper.make_node('Concat', ['m', 'n'], [names[1]], axis=1)]
    model = helper.make_model(helper.make_graph(nodes, 'g', [x], [y]),
                              opset_imports=[helper.make_opsetid('', 13)])
    model.ir_version = 9
    if meta is not None:
        entry = model.metadata_props.add()
        entry.key, entry.value = 'dataset_meta', meta
    onnx.save(model, str(path))
    return str(path)


def _reference(spikes):
    mean = spikes.float().mean(1, keepdim=True)
    return torch.cat([mean, -mean], 1)


def _spikes(batch, seed=0):
    generator = torch.Generator().manual_seed(seed)
    return (torch.rand(batch, T, H, W, generator=generator) < 0.4).float()


def test_a_float16_model_is_fed_float16_and_gives_float32(tmp_path):
    runner = OnnxSpikeSegmentor(_model(tmp_path / 'h.onnx',
                                       TensorProto.FLOAT16))
    spikes = _spikes(3)
    got = runner(spikes)
    assert got.dtype == torch.float32 and got.shape == (3, 2, H, W)
    # float16's rounding of the means k/3
    assert torch.allclose(got, _reference(spikes), atol=1e-3)


def test_a_fixed_batch_model_runs_any_batch_in_chunks(tmp_path):
    runner = OnnxSpikeSegmentor(_model(tmp_path / 'b2.onnx',
                                       in_shape=(2, T, H, W),
                                       out_shape=(2, 2, H, W)))
    for batch in (1, 2, 3, 5):
        spikes = _spikes(batch, seed=batch)
        assert torch.allclose(runner(spikes), _reference(spikes))


@pytest.mark.parametrize('options, words', [
    (dict(out_shape=('n', T), nodes=[helper.make_node(
        'ReduceMean', ['spikes'], ['logits'], axes=[2, 3], keepdims=0)]),
     "output 'logits' is \\['n', 3\\]"),
    (dict(out_shape=('n', T, H, W + 1), nodes=[
        helper.make_node('Constant', [], ['p'], value=helper.make_tensor(
            'p', TensorProto.INT64, [8], [0, 0, 0, 0, 0, 0, 0, 1])),
        helper.make_node('Pad', ['spikes', 'p'], ['logits'])]),
     'dimension 3 is 6'),
    (dict(in_shape=('n', T, H)), 'takes \\(batch, T, H, W\\)'),
    (dict(in_shape=('n', 't', H, W)), 'with T, H, W fixed'),
    (dict(in_type=TensorProto.STRING, out_type=TensorProto.FLOAT,
          nodes=[helper.make_node('Constant', [], ['logits'],
                                  value_float=0.0)]),
     'holds tensor\\(string\\)'),
    (dict(out_type=TensorProto.INT64, nodes=[
        helper.make_node('Cast', ['spikes'], ['logits'], to=7)]),
     'holds tensor\\(int64\\)'),
    (dict(names=('x', 'logits')), "input is named 'spikes'"),
    (dict(out_shape=('n', T, H, W), nodes=[helper.make_node(
        'Identity', ['spikes'], ['logits'])]), None),  # K=3 against 2 below
])
def test_models_of_another_interface_are_refused_naming_the_file(
        tmp_path, options, words):
    if words is None:  # the class count against the recorded classes
        meta = json.dumps(dict(classes=['a', 'b'],
                               palette=[[0, 0, 0], [1, 1, 1]]))
        options = dict(options, meta=meta)
        words = 'logits have 3 classes but its dataset_meta names 2'
    path = _model(tmp_path / 'other.onnx', **options)
    with pytest.raises(ValueError, match=words) as error:
        OnnxSpikeSegmentor(path)
    assert 'other.onnx' in str(error.value)


def test_a_result_of_another_shape_is_refused_at_run_time(tmp_path):
    """A graph that declares (batch, 2, H, W) logits but computes
    (batch, T): ONNX Runtime's shape inference gives up on the declared
    rank, so the result is checked when it comes."""
    path = _model(tmp_path / 'flat.onnx', nodes=[helper.make_node(
        'ReduceMean', ['spikes'], ['logits'], axes=[2, 3], keepdims=0)])
    runner = OnnxSpikeSegmentor(path)
    with pytest.raises(ValueError, match='flat.onnx: gave logits of shape '
                       '\\(1, 3\\); an exported spike segmentor gives'):
        runner(_spikes(1))


@pytest.mark.parametrize('meta, words', [
    ('{"classes": ["a", "b"], "palette": [[0, 0, 300], [1, 1, 1]]}',
     'palette row 0 is \\[0, 0, 300\\]'),
    ('{"classes": ["a", "b"], "palette": [[0, 0], [1, 1, 1]]}',
     'palette row 0'),
    ('{"classes": ["a", 2], "palette": [[0, 0, 0], [1, 1, 1]]}',
     'classes must be a non-empty list of names'),
    ('{"classes": ["a"], "palette": [[0, 0, 0], [1, 1, 1]]}',
     '1 classes but 2 palette rows'),
    ('[' * (MAX_JSON_DEPTH + 1) + ']' * (MAX_JSON_DEPTH + 1),
     'nested too deeply \\(33 levels'),
    ('{"classes": ', 'must be JSON'),
    ('[1, 2]', 'must be a mapping'),
])
def test_malformed_metadata_is_refused_naming_the_file(tmp_path, meta,
                                                       words):
    path = _model(tmp_path / 'meta.onnx', meta=meta)
    with pytest.raises(ValueError, match=words) as error:
        OnnxSpikeSegmentor(path)
    assert 'meta.onnx' in str(error.value)


@pytest.mark.parametrize('state, words', [
    (dict(state_dict=[1, 2]), 'state_dict must map parameter names'),
    (dict(state_dict={'w': [1.0]}), "'w' -> list"),
    ({1: torch.zeros(1)}, '1 -> Tensor'),
    (dict(state_dict={}, meta='x'), 'meta must be a mapping'),
    (dict(state_dict={}, meta=dict(dataset_meta=[1])),
     'meta.dataset_meta must be a mapping'),
    (dict(state_dict={}, meta=dict(dataset_meta=dict(
        classes=['a'], palette=[[300, 0, 0]]))), 'palette row 0 is'),
    (dict(state_dict={}, meta=dict(dataset_meta=dict(
        classes=['a'], palette=[[1.5, 0, 0]]))), 'palette row 0 is'),
    (dict(state_dict={}, meta=dict(dataset_meta=dict(
        classes='ab', palette=[[1, 0, 0]]))), 'classes must be'),
    (dict(state_dict={}, meta=dict(dataset_meta=dict(
        classes=['a', 'b']))), '2 classes but 19 palette rows'),
])
def test_malformed_checkpoints_are_refused_before_the_model_is_built(
        tmp_path, state, words):
    path = str(tmp_path / 'bad.pth')
    torch.save(state, path)
    with pytest.raises(CheckpointError, match=words) as error:
        load_segmentor(None, path)  # no config needed: refused first
    assert 'bad.pth' in str(error.value)


_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-5, 300) | st.floats(
        allow_nan=False) | st.text(max_size=3),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.text(max_size=3), inner, max_size=4), max_leaves=12)


@settings(max_examples=200, deadline=None)
@given(classes=_VALUES, palette=_VALUES)
def test_dataset_meta_is_valid_or_refused(classes, palette):
    """Any value: either a well-formed meta comes back, or a
    CheckpointError naming the source; nothing else escapes."""
    try:
        meta = check_dataset_meta('f.pth', dict(classes=classes,
                                                palette=palette))
    except CheckpointError as err:
        assert str(err).startswith('f.pth: dataset_meta')
        return
    assert all(isinstance(c, str) for c in meta['classes'])
    assert len(meta['palette']) == len(meta['classes']) > 0
    assert all(len(row) == 3 and all(type(v) is int and 0 <= v <= 255
                                     for v in row) for row in meta['palette'])


def _depth(value):
    if isinstance(value, list):
        return 1 + max(map(_depth, value), default=0)
    if isinstance(value, dict):
        return 1 + max(map(_depth, value.values()), default=0)
    return 0


@settings(max_examples=200, deadline=None)
@given(value=st.recursive(
    st.integers() | st.text(alphabet='[]{}"\\ab', max_size=5),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(
        st.text(alphabet='[]{}"\\ab', max_size=3), inner, max_size=3),
    max_leaves=30))
def test_json_depth_counts_nesting_not_brackets_in_strings(value):
    text = json.dumps(value)
    assert json_depth(text) == _depth(value)
    if _depth(value) <= MAX_JSON_DEPTH:
        assert parse_json(text, 'src', 'thing') == value


def test_json_files_over_the_limits_are_refused_naming_the_file(tmp_path):
    deep = tmp_path / 'deep.json'
    deep.write_text('{"a": ' * 10_000 + '1' + '}' * 10_000)
    with pytest.raises(ValueError, match='deep.json: a marker nested too '
                       'deeply \\(10000 levels'):
        load_json_file(str(deep), 'marker')
    big = tmp_path / 'big.json'
    big.write_text(json.dumps(['x' * 1000] * 10))
    with pytest.raises(ValueError, match='big.json: a marker larger than '
                       '5000 bytes'):
        load_json_file(str(big), 'marker', limit=5000)
    assert load_json_file(str(big), 'marker') == ['x' * 1000] * 10


def test_the_export_refuses_a_bad_palette_before_writing(tmp_path,
                                                         load_tool):
    """A palette value of 300 in the checkpoint: refused naming the file
    and the row, and nothing written."""
    checkpoint = str(tmp_path / 'model.pth')
    torch.save(dict(state_dict={}, meta=dict(dataset_meta=dict(
        classes=['a', 'b'], palette=[[0, 0, 0], [10, 300, 0]]))),
        checkpoint)
    tool = load_tool('tools/deployment/pytorch2onnx.py')
    config = 'configs/segformer_b0_raw.py'
    with pytest.raises(SystemExit, match='model.pth \\(meta.dataset_meta\\)'
                       ': dataset_meta palette row 1 is \\[10, 300, 0\\]'):
        tool.main([config, checkpoint, '--shape', '9', '32', '64', '--out',
                   str(tmp_path / 'm.onnx'), '--cfg-options', 'num_steps=9'])
    assert [p.name for p in tmp_path.iterdir()] == ['model.pth']


@pytest.mark.parametrize('frames, num_steps, words', [
    ((12, H, W), 5, 'exported for windows of T=3 but the config\'s is '
     'num_steps=5; add --cfg-options num_steps=3'),
    ((12, H + 2, W), T, f'exported for {H}x{W} frames but .*rec.npy has '
     f'{H + 2}x{W}; export again with --shape {T} {H + 2} {W}'),
    ((60, H, W), 21, 'gives 21 classes and records no palette; the '
     'default \\(Spike-Cityscapes\\) has 19 colours'),
])
def test_the_onnx_walk_checks_the_model_against_config_and_recording(
        tmp_path, load_tool, frames, num_steps, words):
    """Before a walk: the file's T against the config's window, its H, W
    against the recording's frames; more classes than the default palette
    has colours, where the file records none."""
    from wgse_mmseg.fileio.spike_files import save_spikes
    model = _model(tmp_path / 'm.onnx') if num_steps != 21 else _model(
        tmp_path / 'm.onnx', in_shape=('n', 21, H, W),
        out_shape=('n', 21, H, W),
        nodes=[helper.make_node('Identity', ['spikes'], ['logits'])])
    recording = str(tmp_path / 'rec.npy')
    save_spikes(recording, np.zeros(frames, np.uint8))
    demo = load_tool('tools/demo.py')
    with pytest.raises(SystemExit, match=words):
        demo.main([recording, 'configs/segformer_b0_raw.py', model,
                   '--backend', 'onnxruntime', '--stride', '3',
                   '--out-file', str(tmp_path / 'walk.gif'),
                   '--cfg-options', f'num_steps={num_steps}'])


def test_non_finite_logits_are_an_error_not_a_label(tmp_path):
    """log(mean) of an all-zero window is -inf: no argmax of it is a
    class."""
    path = _model(tmp_path / 'log.onnx', nodes=[
        helper.make_node('ReduceMean', ['spikes'], ['m'], axes=[1],
                         keepdims=1),
        helper.make_node('Log', ['m'], ['l']),
        helper.make_node('Concat', ['l', 'l'], ['logits'], axis=1)])
    runner = OnnxSpikeSegmentor(path)
    assert torch.isfinite(runner(torch.ones(1, T, H, W))).all()
    with pytest.raises(ValueError, match='log.onnx: gave 40 non-finite '
                       'logits of 40'):
        runner(torch.zeros(1, T, H, W))
