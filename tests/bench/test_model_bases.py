"""Spike input into MMSeg's model bases: a base by the documented recipe
trains two iterations and predicts, or is refused naming why; never a raw
error. The whole sweep (every base) makes docs/models.md; here a sample
of architectures, each kind of outcome, and the page covering every base."""
import os.path as osp

import pytest

import wgse_mmseg
from wgse_bench.model_bases import model_bases, try_model_base

wgse_mmseg.register_all_modules()
ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


@pytest.mark.parametrize('base, status, reason', [
    ('bisenetv2.py', 'trains', ''),  # in_channels absent: added
    ('fcn_unet_s5-d16.py', 'trains', ''),  # 2 classes in its base: 19
    ('stdc.py', 'trains', ''),  # the stem in backbone_cfg
    ('segformer_mit-b0.py', 'trains', ''),
    ('lraspp_m-v3-d8.py', 'refused', 'has no in_channels argument'),
    ('ccnet_r50-d8.py', 'refused', 'needs compiled mmcv ops'),
])
def test_a_model_base_trains_with_spikes_or_is_refused_naming_why(
        base, status, reason):
    row = try_model_base(f'mmseg::_base_/models/{base}', num_steps=4,
                         side=32)
    assert row['status'] == status, row
    assert reason in row['reason']


def test_the_models_page_lists_every_base():
    page = open(osp.join(ROOT, 'docs', 'models.md'), encoding='utf-8').read()
    bases = model_bases()
    assert len(bases) >= 50
    missing = [b for b in bases if f'| {osp.basename(b)} ' not in page]
    assert not missing, missing
