"""The spike data preprocessor owns and runs the enhancer whatever segmentor
holds it: the shipped configs use MMSeg's own ``EncoderDecoder``, a
``CascadeEncoderDecoder`` (OCRNet-HRNet) takes spikes and WGSE by its
``in_channels`` and data preprocessor alone, the project's benchmark counts
the enhancer's FLOPs, and checkpoints of the earlier ``SpikeEncoderDecoder``
still load."""
import os.path as osp

import torch
from mmengine.analysis import get_model_complexity_info
from mmengine.optim import OptimWrapper

import wgse_mmseg
from mmseg.registry import MODELS
from wgse_bench.segmentation import count_flops, make_spike_batch
from wgse_mmseg.utils.config import load_config

wgse_mmseg.register_all_modules()

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SEGFORMER_WGSE = 'segformer_b0_wgse'
SEGFORMER_RAW = 'segformer_b0_raw'


def _model(name):
    cfg = load_config(osp.join(ROOT, 'configs', f'{name}.py'),
                      dict(num_steps=9))
    return MODELS.build(cfg.model).eval()


def _calls(module):
    """The inputs of every call of ``module``, as a list that fills up."""
    calls = []
    module.register_forward_pre_hook(lambda _, args: calls.append(args[0]))
    return calls


def test_the_enhancer_runs_once_in_the_data_preprocessor():
    model = _model(SEGFORMER_WGSE)
    assert type(model).__name__ == 'EncoderDecoder'  # MMSeg's own
    enhancer = model.data_preprocessor.enhancer
    enhanced, backbone = _calls(enhancer), _calls(model.backbone)
    spikes = (torch.rand(9, 32, 64) < 0.3).to(torch.uint8)
    with torch.no_grad():
        batch = model.data_preprocessor(dict(inputs=[spikes]))
        want = enhancer(spikes[None].float())
        model(batch['inputs'], mode='tensor')
    assert len(enhanced) == 2  # the preprocessor's call and ours
    torch.testing.assert_close(enhanced[0], spikes[None].float())
    torch.testing.assert_close(batch['inputs'], want)
    assert len(backbone) == 1  # the segmentor's forward runs it no more
    torch.testing.assert_close(backbone[0], want)


def test_the_benchmark_counts_the_enhancers_flops():
    inputs = (torch.rand(1, 9, 32, 64) < 0.3).float()
    wgse, raw = _model(SEGFORMER_WGSE), _model(SEGFORMER_RAW)
    enhancer = get_model_complexity_info(
        wgse.data_preprocessor.enhancer, inputs=inputs, show_table=False,
        show_arch=False)
    assert enhancer['flops'] > 0
    with_wgse = count_flops(wgse, 9, (32, 64))
    without = count_flops(raw, 9, (32, 64))
    assert with_wgse['enhancer'] == enhancer['flops']
    assert with_wgse['total'] - without['total'] == enhancer['flops']
    # mmengine's counter over the whole model sees its parameters
    counts = {name: get_model_complexity_info(
        model, inputs=inputs, show_table=False, show_arch=False)['params']
        for name, model in ((SEGFORMER_WGSE, wgse), (SEGFORMER_RAW, raw))}
    assert counts[SEGFORMER_WGSE] - counts[SEGFORMER_RAW] == \
        enhancer['params']


def test_a_checkpoint_of_the_earlier_segmentor_loads(tmp_path):
    """Configs that name ``SpikeEncoderDecoder`` build MMSeg's segmentor
    with the same parameter names (``data_preprocessor.enhancer.*``)."""
    cfg = load_config(osp.join(ROOT, 'configs', f'{SEGFORMER_WGSE}.py'),
                      dict(num_steps=9))
    old = MODELS.build(dict(cfg.model, type='SpikeEncoderDecoder'))
    assert type(old).__name__ == 'EncoderDecoder'
    state = old.state_dict()
    assert any(k.startswith('data_preprocessor.enhancer.') for k in state)
    path = tmp_path / 'old.pth'
    torch.save(dict(state_dict=state), path)
    new = MODELS.build(cfg.model)
    from mmengine.runner import load_checkpoint
    load_checkpoint(new, str(path), strict=True, logger='silent')
    for name, value in new.state_dict().items():
        assert torch.equal(value, state[name]), name


def test_a_cascade_segmentor_takes_spikes_by_two_changes(tmp_path):
    """OCRNet-HRNet (MMSeg's ``CascadeEncoderDecoder``): its RGB config with
    only ``in_channels`` and the data preprocessor changed trains a step,
    the enhancer's output reaching the backbone and its weights moving."""
    child = tmp_path / 'ocrnet_hr18_wgse.py'
    child.write_text(
        "_base_ = ['mmseg::_base_/models/ocrnet_hr18.py',\n"
        f"          {osp.join(ROOT, 'configs/_base_/datasets/spike_cityscapes.py')!r},\n"  # noqa: E501
        f"          {osp.join(ROOT, 'configs/_base_/models/wgse.py')!r}]\n"
        'model = dict(\n'
        '    data_preprocessor=dict(_delete_=True,\n'
        '                           **_base_.spike_data_preprocessor,\n'
        '                           enhancer=_base_.wgse),\n'
        '    backbone=dict(in_channels={{_base_.num_steps}}))\n')
    cfg = load_config(str(child), dict(num_steps=9, crop_size='32,64'))
    assert cfg.model.backbone.in_channels == 9
    model = MODELS.build(cfg.model)  # no init_weights: no RGB download
    assert type(model).__name__ == 'CascadeEncoderDecoder'
    enhancer = model.data_preprocessor.enhancer
    before = {k: v.clone() for k, v in enhancer.state_dict().items()}
    enhanced, backbone = _calls(enhancer), _calls(model.backbone)
    outputs = []
    enhancer.register_forward_hook(lambda *args: outputs.append(args[2]))
    batch = make_spike_batch(9, 32, 64, batch_size=2, labels=True)
    model.train()
    optim = OptimWrapper(torch.optim.SGD(model.parameters(), lr=0.1))
    losses = model.train_step(batch, optim)
    assert {'decode_0.loss_ce', 'decode_1.loss_ce'} <= set(losses)
    assert all(torch.isfinite(v).all() for v in losses.values())
    assert len(enhanced) == len(backbone) == 1
    assert enhanced[0].shape == (2, 9, 32, 64)
    assert torch.equal(backbone[0], outputs[0])  # what WGSE made of them
    moved = [k for k, v in enhancer.state_dict().items()
             if not torch.equal(v, before[k])]
    assert moved  # the loss reached the enhancer's parameters
