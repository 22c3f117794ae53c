"""Weights record the T and the enhancer they were trained with: loading
them into a model of another T or enhancer is refused naming both, by
every loader (torch's, mmengine's, MMSeg's ``init_model``, the tools'),
never a warning over a random stem."""
import os.path as osp

import pytest
import torch
from hypothesis import given, strategies as st
from mmengine.runner.checkpoint import load_checkpoint

import wgse_mmseg
from mmengine.registry import init_default_scope
from mmseg.apis import init_model
from mmseg.registry import MODELS
from wgse_mmseg.models import SpikeModelMismatchError
from wgse_mmseg.models.data_preprocessor import decode_record, encode_record

wgse_mmseg.register_all_modules()
ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


def _model(config, num_steps):
    cfg = wgse_mmseg.load_config(osp.join(ROOT, 'configs', config),
                                 {'num_steps': num_steps})
    init_default_scope('mmseg')
    return cfg, MODELS.build(cfg.model)


@given(num_steps=st.one_of(st.none(), st.integers(1, 10 ** 6)),
       name=st.text('ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghij_0123456789',
                    max_size=40))
def test_a_record_round_trips(num_steps, name):
    assert decode_record(encode_record(num_steps, name)) == (num_steps, name)


@pytest.mark.parametrize('record', [
    torch.empty(0, dtype=torch.int64), torch.tensor([[1, 2]]),
    torch.tensor([5.0]), torch.tensor([4, 300]), torch.tensor([-7]), 'x'])
def test_what_is_not_a_record_is_none(record):
    assert decode_record(record) is None


def test_weights_of_another_t_or_enhancer_are_refused_by_every_loader(
        tmp_path):
    _, trained = _model('segformer_b0_wgse.py', 9)
    path = str(tmp_path / 'epoch_1.pth')
    torch.save(dict(state_dict=trained.state_dict(), meta={}), path)
    cfg, other_t = _model('segformer_b0_wgse.py', 11)
    expected = r'trained with num_steps=9, the model is built for ' \
        r'num_steps=11.*--cfg-options num_steps=9'
    with pytest.raises(SpikeModelMismatchError, match=expected):
        other_t.load_state_dict(trained.state_dict())
    with pytest.raises(SpikeModelMismatchError, match=expected):
        load_checkpoint(other_t, path, map_location='cpu')
    with pytest.raises(SpikeModelMismatchError, match=expected):
        init_model(cfg, path, device='cpu')
    _, raw = _model('segformer_b0_raw.py', 9)
    with pytest.raises(SpikeModelMismatchError, match='trained with '
                       'enhancer WGSE, the model has None'):
        load_checkpoint(raw, path, map_location='cpu')
    # the same T and enhancer load, and give the trained model's outputs
    cfg, same = _model('segformer_b0_wgse.py', 9)
    loaded = init_model(cfg, path, device='cpu')
    spikes = torch.randint(0, 2, (1, 9, 32, 32)).float()
    trained.eval()
    with torch.no_grad():
        assert torch.equal(loaded(spikes, mode='tensor'),
                           trained(spikes, mode='tensor'))


def test_weights_saved_without_a_record_still_load(tmp_path):
    _, trained = _model('pspnet_raw.py', 9)
    state = {k: v for k, v in trained.state_dict().items()
             if not k.endswith('_extra_state')}
    _, model = _model('pspnet_raw.py', 9)
    model.load_state_dict(state, strict=True)
