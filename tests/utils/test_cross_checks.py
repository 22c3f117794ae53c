"""Cross-field checks at the start of training: a crop
below the smallest input the built model takes, or a batch its batch norms
cannot train on, refused before any data is read, naming the smallest
value that works."""
import os.path as osp

import pytest
import torch
from hypothesis import given, settings, strategies as st

import wgse_mmseg
from mmengine.registry import init_default_scope
from mmseg.registry import MODELS
from wgse_mmseg.utils.config import load_config
from wgse_mmseg.utils.cross_checks import (ModelFitError,
                                           check_training_fits,
                                           smallest_input_side)

wgse_mmseg.register_all_modules()
ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
T = 9


def _built(config, **options):
    cfg = load_config(osp.join(ROOT, 'configs', config),
                      dict(num_steps=T, **options))
    init_default_scope(cfg.get('default_scope', 'mmseg'))
    return cfg, MODELS.build(cfg.model)


@settings(max_examples=200, deadline=None)
@given(smallest=st.integers(1, 5000), start=st.integers(1, 5000))
def test_the_search_finds_the_smallest_side(smallest, start):
    probes = []

    def runs(side):
        probes.append(side)
        return side >= smallest
    assert smallest_input_side(runs, start) == smallest
    assert len(probes) <= 2 * 14 + 2  # doubling, then bisection


def test_a_model_that_runs_on_nothing_is_named():
    assert smallest_input_side(lambda side: False, 7) is None


def _segformer_smallest_side(cfg):
    """From SegFormer's definition: stage 1's patch embedding (kernel 7,
    stride 4, padding 3) must leave at least ``sr_ratio`` pixels for the
    spatial-reduction convolution of its attention."""
    backbone = cfg.model.backbone  # MixVisionTransformer's defaults:
    kernel = backbone.get('patch_sizes', [7, 3, 3, 3])[0]
    stride = backbone.get('strides', [4, 2, 2, 2])[0]
    ratio = backbone.get('sr_ratios', [8, 4, 2, 1])[0]
    side = 1
    while (side + 2 * (kernel // 2) - kernel) // stride + 1 < ratio:
        side += 1
    return side


def test_a_crop_below_the_backbones_minimum_is_refused():
    cfg, model = _built('segformer_b0_wgse.py', crop_size=(16, 32))
    smallest = _segformer_smallest_side(cfg)
    assert smallest == 29
    with pytest.raises(ModelFitError) as error:
        check_training_fits(cfg, model)
    message = str(error.value)
    assert 'segformer_b0_wgse.py: crop_size=(16, 32)' in message
    assert f'{smallest}x{smallest}' in message
    assert f'crop_size={smallest},32 or larger' in message
    for crop in ((smallest, smallest), (smallest, 300)):
        cfg, model = _built('segformer_b0_wgse.py', crop_size=crop)
        check_training_fits(cfg, model)
    cfg, model = _built('segformer_b0_wgse.py',
                        crop_size=(300, smallest - 1))
    with pytest.raises(ModelFitError, match=f'{smallest}x{smallest}'):
        check_training_fits(cfg, model)


def test_a_batch_of_one_before_a_pooled_batch_norm_is_refused():
    """PSPNet's 1x1 pooling branch has a batch norm: one window a batch
    gives it one value per channel."""
    cfg, model = _built('pspnet_raw.py', crop_size=(32, 32),
                        **{'train_dataloader.batch_size': 1})
    with pytest.raises(ModelFitError, match='train_dataloader.batch_size=1 '
                       'does not train this model.*the smallest batch_size '
                       'that works is 2'):
        check_training_fits(cfg, model)
    cfg, model = _built('pspnet_raw.py', crop_size=(32, 32),
                        **{'train_dataloader.batch_size': 2})
    check_training_fits(cfg, model)


def test_the_checks_leave_the_model_and_the_generators_as_they_were():
    cfg, model = _built('pspnet_wgse.py', crop_size=(40, 48),
                        **{'train_dataloader.batch_size': 1})
    model.train()
    state = {k: v.clone() for k, v in model.state_dict().items()}
    torch.manual_seed(5)
    expected = torch.rand(3)
    torch.manual_seed(5)
    with pytest.raises(ModelFitError):
        check_training_fits(cfg, model)
    assert torch.equal(torch.rand(3), expected)
    assert all(torch.equal(state[k], v) for k, v in
               model.state_dict().items())
    assert all(m.training for m in model.modules())


def _user_model(tmp_path, base, num_steps=T, plain=False, **options):
    """A user's config for MMSeg's model base ``base`` by the documented
    recipe without its ``in_channels`` line, and its built model; with
    ``plain``, read by mmengine alone (no spike settings applied)."""
    from mmengine.config import Config
    path = tmp_path / f'{base}_spikes.py'
    path.write_text(
        f"_base_ = ['mmseg::_base_/models/{base}.py', "
        f"{osp.join(ROOT, 'configs/_base_/datasets/spike_cityscapes.py')!r}]"
        "\nnorm_cfg = dict(type='BN', requires_grad=True)\n"
        "model = dict(data_preprocessor=dict(\n"
        "    _delete_=True, **_base_.spike_data_preprocessor))\n")
    cfg = Config.fromfile(str(path)) if plain else load_config(
        str(path), dict(num_steps=num_steps, **options))
    init_default_scope('mmseg')
    return cfg, MODELS.build(cfg.model)


def test_the_checks_give_back_the_very_tensors_of_shared_modules(tmp_path):
    """The shape-only forward swaps every parameter and buffer for a meta
    one and back: a module two parents share (ANN's key and query
    projection) and everything else hold the same tensors afterwards."""
    cfg, model = _user_model(tmp_path, 'ann_r50-d8', crop_size=(48, 48))
    shared = model.decode_head.context.stages[0]
    assert shared.key_project is shared.query_project
    held = [*model.named_parameters(remove_duplicate=False),
            *model.named_buffers(remove_duplicate=False)]
    check_training_fits(cfg, model)
    after = dict([*model.named_parameters(remove_duplicate=False),
                  *model.named_buffers(remove_duplicate=False)])
    assert all(after[name] is tensor and tensor.device.type == 'cpu'
               for name, tensor in held)


def _peak_growth_mb(call):
    import resource
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    try:
        call()
    finally:
        after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return (after - before) / 1024


def test_a_stem_of_the_wrong_width_is_named_with_its_field(tmp_path):
    """The config read without the spike settings keeps ResNet's three
    input channels: the check names the stem and the field, at once and
    without allocating trial inputs (it once grew them to 16384x16384)."""
    cfg, model = _user_model(tmp_path, 'pspnet_r50-d8', plain=True)
    cfg.crop_size = (512, 1024)
    with pytest.raises(ModelFitError) as error:
        grown = _peak_growth_mb(lambda: check_training_fits(cfg, model))
    message = str(error.value)
    assert "layer backbone.stem.0 (Conv2d) takes 3 input channels but is " \
        "given the spikes' 129 channels (num_steps=129)" in message
    assert 'set model.backbone.in_channels=129' in message
    # loaded by the package, the same config trains: T reached the stem
    cfg, model = _user_model(tmp_path, 'pspnet_r50-d8')
    assert model.backbone.stem[0].in_channels == T
    grown = _peak_growth_mb(lambda: check_training_fits(cfg, model))
    assert grown < 300, grown


def test_a_backbone_that_takes_no_in_channels_is_refused_naming_it(
        tmp_path):
    cfg, model = _user_model(tmp_path, 'lraspp_m-v3-d8')
    with pytest.raises(ModelFitError, match=r'layer backbone\.layer0\.conv '
                       r'.*takes 3 input channels.*model\.backbone '
                       r'\(MobileNetV3\) has no in_channels argument'):
        check_training_fits(cfg, model)


def test_a_crop_of_any_size_is_checked_in_bounded_memory(tmp_path):
    """A forward of shapes only: a 4096x8192 crop (its input alone 1.2
    GB at T=9) costs the check no more memory than a small one."""
    for crop in ((512, 1024), (4096, 8192)):
        cfg, model = _built('pspnet_wgse.py', crop_size=crop)
        grown = _peak_growth_mb(lambda: check_training_fits(cfg, model))
        assert grown < 300, (crop, grown)


def test_a_head_of_another_class_count_is_named(tmp_path):
    """MMSeg's UNet base predicts 2 classes; the data has 19."""
    cfg, model = _user_model(tmp_path, 'fcn_unet_s5-d16')
    with pytest.raises(ModelFitError, match=r'model\.decode_head\.'
                       r'num_classes=2, but the data has 19 classes.*set '
                       r'num_classes=19 in model\.decode_head'):
        check_training_fits(cfg, model)
    # STDC's boundary head predicts its own two classes: not refused
    cfg, model = _user_model(tmp_path, 'stdc')
    check_training_fits(cfg, model)
