"""Spike input into MMSeg's model bases: every base by the documented
recipe trains an iteration and predicts, or is refused naming why;
never a raw error. The same sweep at a larger size makes docs/models.md,
which must list every base with the outcome found here."""
import os.path as osp

import pytest

import wgse_mmseg
from wgse_bench.model_bases import model_bases, try_model_base

wgse_mmseg.register_all_modules()
ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


#: what some bases must give (the rest: trains or refused with a reason)
EXPECTED = {
    'bisenetv2.py': ('trains', ''),  # in_channels absent: added
    'fcn_unet_s5-d16.py': ('trains', ''),  # 2 classes in its base: 19
    'stdc.py': ('trains', ''),  # the stem in backbone_cfg
    'segformer_mit-b0.py': ('trains', ''),
    'lraspp_m-v3-d8.py': ('refused', 'has no in_channels argument'),
    'ccnet_r50-d8.py': ('refused', 'needs compiled mmcv ops'),
    'upernet_beit.py': ('refused', 'takes only its fixed input size'),
    'vpd_sd.py': ('refused', 'has no decode_head'),
}
PAGE = osp.join(ROOT, 'docs', 'models.md')


def _made_on_this_stack():
    """Whether docs/models.md was made with the installed mmcv."""
    from wgse_bench.machine import machine_record
    return f'mmcv {machine_record()["mmcv"]}' in open(
        PAGE, encoding='utf-8').read().split('\n\n| model base')[0]


_PAGE_STACK = _made_on_this_stack()


def _page_status(name):
    for line in open(PAGE, encoding='utf-8'):
        if line.startswith(f'| {name} '):
            return line.split('|')[2].strip()
    return None


#: the bases that take seconds each (the largest: SETR's ViT-L, 13-21 s on
#: the 2-core CPU), which the suite starts first
LARGE = ('setr_mla.py', 'setr_naive.py', 'setr_pup.py',
         'twins_pcpvt-s_upernet.py', 'dpt_vit-b16.py', 'upernet_beit.py',
         'ocrnet_hr18.py', 'apcnet_r50-d8.py', 'upernet_swin.py',
         'upernet_r50.py', 'upernet_vit-b16_ln_mln.py', 'fcn_hr18.py')


@pytest.mark.parametrize('base', [
    pytest.param(b, marks=pytest.mark.long(8)) if osp.basename(b) in LARGE
    else b for b in model_bases()])
def test_a_model_base_trains_with_spikes_or_is_refused_naming_why(base):
    row = try_model_base(base, num_steps=2, side=48, iterations=1)
    name = osp.basename(base)
    assert row['status'] in ('trains', 'refused'), row
    assert row['status'] == 'trains' or row['reason'], row
    status, reason = EXPECTED.get(name, (row['status'], ''))
    assert row['status'] == status and reason in row['reason'], row
    if _PAGE_STACK:  # the page says what this stack gives (the fork's
        # mmcv lacks what PointRend imports)
        assert _page_status(name) == row['status'], (name, row)


def test_the_models_page_lists_every_base():
    page = open(PAGE, encoding='utf-8').read()
    bases = model_bases()
    assert len(bases) >= 50
    missing = [b for b in bases if f'| {osp.basename(b)} ' not in page]
    assert not missing, missing


@pytest.mark.parametrize('iterations', [0, -1, 1.5, True, '2'])
def test_a_count_of_iterations_that_is_no_count_is_refused(iterations):
    """No row that says a base trains after training nothing."""
    with pytest.raises(ValueError, match='try_model_base: iterations must '
                       'be an integer >= 1'):
        try_model_base('mmseg::_base_/models/fcn_r50-d8.py',
                       iterations=iterations)
