"""ONNX export of spike segmentors (wgse_mmseg.apis.onnx_export,
tools/deployment/pytorch2onnx.py) and running the file
(wgse_mmseg.apis.onnx_segmentor).

The reference is the torch model's own inference path, ``test_step`` on
``uint8`` streams (the data preprocessor, the enhancer on its default
backend, the segmentor and the resize), not the exported wrapper. The
weights are random (the agreement of two implementations of one function
needs no training); the checkpoint route is tested once through the tool.
Each export takes 15 to 20 s on a 2-core CPU at 32x64 (dynamo's tracing and
decompositions), so each graph is exported once: the exported graph is the
enhancer's followed by the segmentor's, and the agreement cases with the
tool's test cover each segmentor's graph (PSPNet, SegFormer) and each
enhancer's (none, TFP, WGSE); the case ``segformer_b0_raw`` checks the
module's file that the runner's tests use.
"""
import os.path as osp
import shutil
from types import SimpleNamespace

import cv2
import numpy as np
import onnx
import pytest
import torch

import wgse_mmseg
from mmengine.registry import init_default_scope
from mmseg.registry import MODELS
from mmseg.structures import SegDataSample
from wgse_mmseg.utils.config import load_config

wgse_mmseg.register_all_modules()  # before mmseg builds anything
from wgse_mmseg.apis import onnx_export  # noqa: E402
from wgse_mmseg.apis.onnx_export import (  # noqa: E402
    LOGITS_TOLERANCE, MIN_ARGMAX_AGREEMENT, SpikeSegmentorGraph,
    compare_with_onnx, export_onnx, random_spikes)
from wgse_mmseg.apis.onnx_segmentor import OnnxSpikeSegmentor  # noqa: E402
from wgse_mmseg.fileio.spike_files import save_spikes  # noqa: E402

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
TOOL = osp.join(ROOT, 'tools', 'deployment', 'pytorch2onnx.py')
T, H, W = 9, 32, 64
ENHANCER = 'model.data_preprocessor.enhancer'
#: the grid's TFP entry (configs/experiments/grid_cpu.py), on a raw config
TFP = {f'{ENHANCER}._delete_': True, f'{ENHANCER}.type': 'TFP',
       f'{ENHANCER}.window': 5}
CASES = {
    'pspnet_tfp': ('pspnet_raw.py', TFP),
    'segformer_b0_raw': ('segformer_b0_raw.py', {}),
    # WGSE's graph (on SegFormer-B0): test_the_tool_exports_a_checkpoint_and_
    # checks_it exports it from a checkpoint and makes the same checks
}


def _model(config, options=None, seed=0):
    cfg = load_config(osp.join(ROOT, 'configs', config),
                      dict(num_steps=T, **(options or {})))
    init_default_scope(cfg.get('default_scope', 'mmseg'))
    torch.manual_seed(seed)
    return MODELS.build(cfg.model).eval()


def _test_step_logits(model, spikes):
    """``(B, K, H, W)`` logits of ``model.test_step`` on ``spikes``
    ``(B, T, H, W)`` given as the data loader gives them (``uint8``)."""
    samples = []
    for _ in spikes:
        sample = SegDataSample()
        sample.set_metainfo(dict(img_shape=(H, W), ori_shape=(H, W),
                                 pad_shape=(H, W)))
        samples.append(sample)
    batch = dict(inputs=list(spikes.to(torch.uint8)), data_samples=samples)
    with torch.no_grad():
        results = model.test_step(batch)
    return torch.stack([r.seg_logits.data for r in results])


def _agreement(got, expected):
    difference = float((got - expected).abs().max())
    scale = max(1.0, float(expected.abs().max()))
    same = float((got.argmax(1) == expected.argmax(1)).float().mean())
    return difference, scale, same


@pytest.mark.long(20)
@pytest.mark.parametrize('case', sorted(CASES))
def test_exported_model_agrees_with_the_torch_model(case, tmp_path, request,
                                                    single_thread):
    config, options = CASES[case]
    model = _model(config, options)
    spikes = random_spikes((3, T, H, W), seed=7)
    expected = _test_step_logits(model, spikes)  # default backends
    if case == EXPORTED:  # the same model's file, made once for the module
        path = request.getfixturevalue('exported')[0]
    else:
        path = export_onnx(SpikeSegmentorGraph(model),
                           str(tmp_path / 'm.onnx'), T, H, W)
    runner = OnnxSpikeSegmentor(path)
    assert runner.input_shape == (T, H, W)
    got = runner(spikes)  # batch 3; the export's example had 2
    assert got.shape == expected.shape == (3, 19, H, W)
    difference, scale, same = _agreement(got, expected)
    assert difference <= LOGITS_TOLERANCE * scale, (difference, scale)
    assert same >= MIN_ARGMAX_AGREEMENT
    # one stream alone: the same logits as in the batch
    torch.testing.assert_close(runner(spikes[1:2]), got[1:2], rtol=0,
                               atol=LOGITS_TOLERANCE * scale)
    # the export's own comparison says the same
    found = compare_with_onnx(SpikeSegmentorGraph(model), path, spikes)
    assert found['ok'] and found['shape'] == [3, 19, H, W]
    assert found['max_abs_diff'] == pytest.approx(difference, abs=1e-5)


def test_wgse_is_exported_through_its_reference_backend():
    model = _model('pspnet_wgse.py')
    assert model.data_preprocessor.enhancer.backend == 'auto'
    SpikeSegmentorGraph(model)
    assert model.data_preprocessor.enhancer.backend == 'reference'


#: the case whose model the module's file holds
EXPORTED = 'segformer_b0_raw'


@pytest.fixture(scope='module')
def exported(built_once):
    """``(path, dataset_meta)``: the model of the case :data:`EXPORTED`
    exported with a dataset meta (once for the run: read only)."""
    meta = dict(classes=[f'c{i}' for i in range(19)],  # the model's 19
                palette=[[i, 2 * i, 255 - i] for i in range(19)])

    def build(path):
        config, options = CASES[EXPORTED]
        export_onnx(SpikeSegmentorGraph(_model(config, options)), path, T, H,
                    W, dataset_meta=meta)
    return built_once('segformer_b0_raw.onnx', build), meta


def test_the_file_records_the_shape_and_the_dataset_meta(exported):
    path, meta = exported
    runner = OnnxSpikeSegmentor(path)
    assert runner.dataset_meta == meta
    graph = onnx.load(path).graph
    dims = [d.dim_value or d.dim_param
            for d in graph.input[0].type.tensor_type.shape.dim]
    assert dims[1:] == [T, H, W] and isinstance(dims[0], str)


@pytest.mark.parametrize('spikes, words', [
    (torch.zeros(1, T + 1, H, W), f'(B, T, H, W) = (\'B\', {T}, {H}, {W})'),
    (torch.zeros(1, T, W, H), 'got (1, 9, 64, 32)'),
    (torch.zeros(T, H, W), 'got (9, 32, 64)'),
    (torch.zeros(0, T, H, W), 'empty batch'),
    (torch.full((1, T, H, W), 0.5), 'only 0 and 1, found [0.5]'),
    (torch.full((1, T, H, W), float('nan')), "only 0 and 1, found ['nan']"),
    (torch.full((1, T, H, W), 2, dtype=torch.uint8), 'found [2]'),
])
def test_bad_input_is_refused_before_the_runtime(exported, spikes, words):
    runner = OnnxSpikeSegmentor(exported[0])
    with pytest.raises(ValueError) as info:
        runner(spikes)
    assert words in str(info.value)


def test_binary_input_of_any_dtype_gives_the_same_logits(exported):
    runner = OnnxSpikeSegmentor(exported[0])
    spikes = random_spikes((1, T, H, W), seed=3)
    logits = runner(spikes)
    assert logits.dtype == torch.float32 and torch.isfinite(logits).all()
    for dtype in (torch.bool, torch.uint8, torch.float64):
        assert torch.equal(runner(spikes.to(dtype)), logits)
    with pytest.raises(TypeError, match='torch.Tensor'):
        runner(spikes.numpy())


def test_files_that_are_not_exported_models(wrong_file_kinds, tmp_path):
    for kind in ('empty', 'text'):
        with pytest.raises(ValueError, match='not a model ONNX Runtime'):
            OnnxSpikeSegmentor(wrong_file_kinds[kind])
    with pytest.raises(FileNotFoundError):
        OnnxSpikeSegmentor(wrong_file_kinds['missing'])
    with pytest.raises(FileNotFoundError):
        OnnxSpikeSegmentor(wrong_file_kinds['directory'])
    # an ONNX model of another signature: one input, but not (B, T, H, W)
    x = onnx.helper.make_tensor_value_info('x', onnx.TensorProto.FLOAT,
                                           ['n', 4])
    y = onnx.helper.make_tensor_value_info('y', onnx.TensorProto.FLOAT,
                                           ['n', 4])
    model = onnx.helper.make_model(onnx.helper.make_graph(
        [onnx.helper.make_node('Relu', ['x'], ['y'])], 'g', [x], [y]),
        opset_imports=[onnx.helper.make_opsetid('', 18)])
    model.ir_version = 9
    other = str(tmp_path / 'relu.onnx')
    onnx.save(model, other)
    with pytest.raises(ValueError, match='takes \\(batch, T, H, W\\)'):
        OnnxSpikeSegmentor(other)
    with pytest.raises(ValueError, match="'cpu' or 'cuda"):
        OnnxSpikeSegmentor(other, device='tpu')
    for threads in (0, 1.5, True):
        with pytest.raises(ValueError, match='threads must be'):
            OnnxSpikeSegmentor(other, threads=threads)


def test_a_model_that_does_not_export_leaves_no_file(tmp_path):
    """TFI's scans (cummax) and its value check do not trace: a clear
    error naming the file, and no file."""
    model = _model('segformer_b0_raw.py', {
        f'{ENHANCER}._delete_': True, f'{ENHANCER}.type': 'TFI'})
    path = tmp_path / 'tfi.onnx'
    with pytest.raises(ValueError, match='tfi.onnx: this model does not '
                       'export to ONNX \\(TFI enhancer'):
        export_onnx(SpikeSegmentorGraph(model), str(path), T, H, W)
    assert not list(tmp_path.iterdir())


@pytest.mark.long(30)
def test_the_tool_exports_a_checkpoint_and_checks_it(tmp_path, capsys,
                                                     load_tool):
    """CONFIG CKPT --shape T H W: weights from the checkpoint (read weights
    only), the check printed; a checkpoint of another T, a shape that is
    not the config's T, refused naming what to change."""
    model = _model('segformer_b0_wgse.py', seed=3)
    checkpoint = str(tmp_path / 'model.pth')
    classes = [f'class {i}' for i in range(19)]  # the model's 19 outputs
    palette = [[i, 2 * i, 3 * i] for i in range(19)]
    torch.save(dict(state_dict=model.state_dict(),
                    meta=dict(dataset_meta=dict(classes=classes,
                                                palette=palette))),
               checkpoint)
    tool = load_tool('tools/deployment/pytorch2onnx.py')
    config = osp.join(ROOT, 'configs', 'segformer_b0_wgse.py')
    out = str(tmp_path / 'model.onnx')
    code = tool.main([config, checkpoint, '--shape', str(T), str(H),
                      str(W), '--out', out, '--cfg-options',
                      f'num_steps={T}'])
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert f'{out}\tinput spikes (batch, {T}, {H}, {W})' in printed
    assert 'argmax agreement 100.000%' in printed and ': ok' in printed
    runner = OnnxSpikeSegmentor(out)
    assert runner.dataset_meta['classes'] == classes
    spikes = random_spikes((3, T, H, W), seed=5)  # the export's had 2
    got = runner(spikes)
    difference, scale, same = _agreement(got, _test_step_logits(model,
                                                                spikes))
    assert difference <= LOGITS_TOLERANCE * scale and same == 1.0
    torch.testing.assert_close(runner(spikes[1:2]), got[1:2], rtol=0,
                               atol=LOGITS_TOLERANCE * scale)

    with pytest.raises(SystemExit, match='--shape T=5 but the config is '
                       'built for num_steps=9'):
        tool.main([config, checkpoint, '--shape', '5', str(H), str(W),
                   '--out', str(tmp_path / 'a.onnx'), '--cfg-options',
                   f'num_steps={T}'])
    with pytest.raises(SystemExit, match='model.pth: the weights were '
                       'trained with num_steps=9, the model is built for '
                       'num_steps=5'):
        tool.main([config, checkpoint, '--shape', '5', str(H), str(W),
                   '--out', str(tmp_path / 'b.onnx'), '--cfg-options',
                   'num_steps=5'])
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        'model.onnx', 'model.pth']

    # the walk of tools/demo.py runs the exported file: the same labels as
    # the torch model's walk on >= 99.9% of pixels, in the file's palette
    demo = load_tool('tools/demo.py')
    recording = tmp_path / 'walk' / 'rec.npy'
    recording.parent.mkdir()
    save_spikes(str(recording), random_spikes((1, 3 * T, H, W), 7)[0]
                .numpy().astype(np.uint8))
    frames = {}
    for backend, model_file in (('pytorch', checkpoint), ('onnxruntime', out)):
        video = recording.parent / f'{backend}.gif'
        demo.main([str(recording), config, model_file, '--device', 'cpu',
                   '--backend', backend, '--stride', str(T),
                   '--out-file', str(video), '--save-frames', '--opacity',
                   '1', '--cfg-options', f'num_steps={T}'])
        frames[backend] = [cv2.imread(str(p)) for p in sorted(
            (recording.parent / f'{backend}_frames').glob('*.png'))]
    assert len(frames['onnxruntime']) == len(frames['pytorch']) >= 2
    for got, expected in zip(frames['onnxruntime'], frames['pytorch']):
        assert (got == expected).all(-1).mean() >= MIN_ARGMAX_AGREEMENT
        # opacity 1: every pixel is a colour of the file's palette
        assert set(map(tuple, got.reshape(-1, 3)[:, ::-1].tolist())) <= set(
            map(tuple, palette))


def test_the_tool_refuses_a_failed_check(tmp_path, capsys, monkeypatch,
                                         load_tool, exported):
    """Beyond the tolerance the tool exits with 1 and says FAILED; the file
    the check ran on does not land, and an earlier export at --out is kept
    as it was. The exporter's result is the module's file of the same model
    (its export is checked above); the tool's check is the real comparison,
    reported beyond the tolerance."""
    model = _model(*CASES[EXPORTED])  # the weights of the file
    checkpoint = str(tmp_path / 'model.pth')
    torch.save(dict(state_dict=model.state_dict()), checkpoint)
    proto = onnx.load(exported[0])
    del proto.metadata_props[:]  # as the exporter gives it

    def exporter(graph, args, **kwargs):
        assert args[0].shape[1:] == (T, H, W) and kwargs['dynamo']
        return SimpleNamespace(model_proto=proto)
    monkeypatch.setattr(torch.onnx, 'export', exporter)
    tool = load_tool('tools/deployment/pytorch2onnx.py')
    real = onnx_export.compare_with_onnx  # the tool's main() imports it
    compared = []

    def skewed(graph, path, spikes):
        found = real(graph, path, spikes)
        compared.append(found['ok'])
        found.update(max_abs_diff=1.0, ok=False)
        return found
    monkeypatch.setattr(onnx_export, 'compare_with_onnx', skewed)
    out = tmp_path / 'm.onnx'
    out.write_bytes(b'an earlier export')
    code = tool.main([osp.join(ROOT, 'configs', 'segformer_b0_raw.py'),
                      checkpoint, '--shape', str(T), str(H), str(W), '--out',
                      str(out), '--cfg-options', f'num_steps={T}'])
    assert code == 1 and 'FAILED' in capsys.readouterr().out
    assert compared == [True]  # the file and the model did agree
    assert out.read_bytes() == b'an earlier export'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['m.onnx',
                                                          'model.pth']


def test_the_comparison_sees_a_model_that_differs(exported):
    """A graph whose first class gets a large bias no longer agrees with
    the file: ``ok`` is false, the difference and the argmax say so."""
    model = _model('segformer_b0_raw.py')  # the weights of the file
    spikes = random_spikes((1, T, H, W), seed=2)
    assert compare_with_onnx(SpikeSegmentorGraph(model), exported[0],
                             spikes)['ok']
    with torch.no_grad():
        model.decode_head.conv_seg.bias[0] += 100
    found = compare_with_onnx(SpikeSegmentorGraph(model), exported[0],
                              spikes)
    assert not found['ok'] and found['max_abs_diff'] > 50
    assert found['argmax_agreement'] < MIN_ARGMAX_AGREEMENT


def test_measure_deployment_times_both_backends(exported, monkeypatch):
    """The deployment benchmark: both backends timed on the same batch,
    windows per second the batch over the median call, the machine named.
    Its export is the module's file of the same model (seed 0 both), as the
    exporter would write it (the export itself is checked above)."""
    from wgse_bench import deployment
    exports = []

    def export(graph, path, num_steps, height, width):
        assert isinstance(graph, SpikeSegmentorGraph)
        exports.append((num_steps, height, width))
        shutil.copyfile(exported[0], path)
        return path
    monkeypatch.setattr(deployment, 'export_onnx', export)
    result = deployment.measure_deployment('segformer_b0_raw', osp.join(
        ROOT, 'configs', 'segformer_b0_raw.py'), None, (T, H, W),
        batch_size=2, repeat=2, warmup=0, threads=1)
    for backend in deployment.BACKENDS:
        seconds = result[backend]['seconds']
        assert len(seconds['samples']) == 2
        assert result[backend]['windows_per_s'] == pytest.approx(
            2 / seconds['median'])
    assert result['shape'] == [T, H, W] and result['batch_size'] == 2
    assert exports == [(T, H, W)]
    assert result['environment']['onnxruntime']
    assert result['threads'] == result['environment']['torch_threads'] == 1
    table = deployment.format_deployment([result])
    assert '| segformer_b0_raw | 9x32x64   |     2 |' in table
    assert 'Machine: ' in table and 'threads: 1' in table
