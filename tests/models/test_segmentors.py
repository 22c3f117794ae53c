"""SpikeEncoderDecoder runs the preprocessor's enhancer in its own forward,
where mmengine's FLOP counter (what MMSeg's get_flops.py uses) sees it."""
import os.path as osp

import torch
from mmengine.analysis import get_model_complexity_info

import wgse_mmseg
from mmseg.registry import MODELS
from wgse_mmseg.utils.config import load_config

wgse_mmseg.register_all_modules()

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SEGFORMER_WGSE = 'segformer_b0_wgse'
SEGFORMER_RAW = 'segformer_b0_raw'


def _model(name):
    cfg = load_config(osp.join(ROOT, 'configs', f'{name}.py'),
                      dict(num_steps=9))
    return MODELS.build(cfg.model).eval()


def test_the_enhancer_runs_once_inside_the_forward():
    model = _model(SEGFORMER_WGSE)
    assert type(model).__name__ == 'SpikeEncoderDecoder'
    assert not model.data_preprocessor.run_enhancer
    calls = []
    model.data_preprocessor.enhancer.register_forward_hook(
        lambda *args: calls.append(1))
    spikes = (torch.rand(9, 32, 64) < 0.3).to(torch.uint8)
    with torch.no_grad():
        batch = model.data_preprocessor(dict(inputs=[spikes]))
        assert torch.equal(batch['inputs'][0], spikes.float())  # batched
        model(batch['inputs'], mode='tensor')
    assert calls == [1]


def test_mmengines_flop_counter_sees_the_enhancer():
    inputs = (torch.rand(1, 9, 32, 64) < 0.3).float()
    counts = {}
    for name in (SEGFORMER_WGSE, SEGFORMER_RAW):
        counts[name] = get_model_complexity_info(
            _model(name), inputs=inputs, show_table=False,
            show_arch=False)
    enhancer = get_model_complexity_info(
        _model(SEGFORMER_WGSE).data_preprocessor.enhancer,
        inputs=inputs, show_table=False, show_arch=False)
    assert enhancer['flops'] > 0
    added = counts[SEGFORMER_WGSE]['flops'] - \
        counts[SEGFORMER_RAW]['flops']
    assert added == enhancer['flops']
    assert counts[SEGFORMER_WGSE]['params'] - \
        counts[SEGFORMER_RAW]['params'] == enhancer['params']
