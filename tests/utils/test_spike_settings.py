"""T, data root and crop size in one place: a child config that sets one
alone, or ``--cfg-options``, gets it into the fields listed for it, with
MMSeg's loader and with the project's, and into no other field."""
import os.path as osp

import pytest
from mmengine.config import Config
from mmengine.registry import RUNNERS

import wgse_mmseg
from wgse_mmseg.utils.config import load_config
from wgse_mmseg.utils.spike_settings import (SpikeSettingsError,
                                             apply_spike_settings)

wgse_mmseg.register_all_modules()

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


def _child(tmp_path, base, body):
    path = tmp_path / 'child.py'
    path.write_text(f"_base_ = [{osp.join(ROOT, 'configs', base)!r}]\n" +
                    body)
    return str(path)


def _t_values(cfg):
    pipelines = [cfg[f'{split}_dataloader'].dataset.pipeline
                 for split in ('train', 'val', 'test')]
    return dict(
        in_channels=cfg.model.backbone.in_channels,
        preprocessor=cfg.model.data_preprocessor.num_steps,
        loaders={step.num_steps for pipeline in pipelines
                 for step in pipeline if step.type == 'LoadSpikeFromFile'})


@pytest.mark.parametrize('base', ['pspnet_wgse.py', 'segformer_b0_raw.py'])
def test_a_child_config_sets_t_once(tmp_path, base):
    child = _child(tmp_path, base, 'num_steps = 41\n')
    cfg = Config.fromfile(child)  # MMSeg's loader: the base's T is stale
    assert _t_values(cfg)['preprocessor'] == 129
    assert apply_spike_settings(cfg) == {
        'model.backbone.in_channels': 129,
        'model.data_preprocessor.num_steps': 129,
        **{f'{split}_dataloader.dataset.pipeline[0].num_steps': 129
           for split in ('train', 'val', 'test')},
        # MMSeg's copies (mmseg.apis.inference_model reads test_pipeline)
        'train_pipeline[0].num_steps': 129, 'test_pipeline[0].num_steps': 129,
        'tta_pipeline[0].num_steps': 129}
    assert cfg.test_pipeline[0].num_steps == 41
    assert _t_values(cfg) == dict(in_channels=41, preprocessor=41,
                                  loaders={41})
    assert apply_spike_settings(cfg) == {}  # and once is enough
    # the project's loader
    assert _t_values(load_config(child)) == _t_values(cfg)


def test_the_configs_runner_builds_the_model_with_the_childs_t(tmp_path):
    """What MMSeg's tools/train.py does with a config with runner_type."""
    cfg = Config.fromfile(_child(tmp_path, 'segformer_b0_wgse.py',
                                 'num_steps = 41\n'))
    cfg.work_dir = str(tmp_path / 'work')
    runner = RUNNERS.build(cfg)
    assert type(runner).__name__ == 'SpikeRunner'
    assert runner.model.backbone.layers[0][0].projection.in_channels == 41
    assert runner.model.data_preprocessor.num_steps == 41
    loader = runner._train_dataloader  # built lazily, still a config
    assert loader['dataset']['pipeline'][0]['num_steps'] == 41


def test_fields_that_disagree_are_listed(tmp_path):
    cfg = Config.fromfile(_child(
        tmp_path, 'pspnet_raw.py',
        'num_steps = 41\n'
        'model = dict(data_preprocessor=dict(num_steps=41))\n'))
    with pytest.raises(SpikeSettingsError) as error:
        apply_spike_settings(cfg)
    message = str(error.value)
    assert 'model.data_preprocessor.num_steps = 41' in message
    assert 'train_dataloader.dataset.pipeline[0].num_steps = 129' in message
    assert '--cfg-options num_steps=41' in message
    with pytest.raises(SpikeSettingsError, match='must be an integer >= 1'):
        apply_spike_settings(Config(dict(num_steps='41')))
    with pytest.raises(SpikeSettingsError, match='must be an integer >= 1'):
        apply_spike_settings(Config(dict(num_steps=0)))


def test_reconstruction_configs_follow_too(tmp_path):
    cfg = load_config(_child(tmp_path, 'reconstruction/wgse_resnet.py',
                             'num_steps = 21\n'))
    assert cfg.model.num_steps == 21
    assert cfg.train_dataloader.dataset.num_steps == 21
    assert cfg.test_dataloader.dataset.pipeline[0].num_steps == 21


def test_a_child_config_sets_crop_size_and_data_root_once(tmp_path):
    child = _child(tmp_path, 'pspnet_wgse.py',
                   "crop_size = (64, 128)\ndata_root = 'elsewhere'\n")
    cfg = load_config(child)
    assert cfg.model.data_preprocessor.size == (64, 128)
    crop = [step for step in cfg.train_dataloader.dataset.pipeline
            if step.type == 'SpikeRandomCrop']
    assert [step.crop_size for step in crop] == [(64, 128)]
    assert {cfg[f'{split}_dataloader'].dataset.data_root
            for split in ('train', 'val', 'test')} == {'elsewhere'}


def test_command_line_values_reach_the_fields_set_from_the_config(tmp_path):
    """A field a config set apart keeps its value: the REDS config's own
    training root, the simulated set's validation crop."""
    reds = osp.join(ROOT, 'configs', 'reconstruction',
                    'wgse_resnet_reds.py')
    cfg = load_config(reds, dict(data_root='val_root', crop_size='32,48',
                                 num_steps=9))
    assert cfg.train_dataloader.dataset.data_root == 'data/reds_train'
    assert cfg.val_dataloader.dataset.data_root == 'val_root'
    assert cfg.test_dataloader.dataset.data_root == 'val_root'
    assert cfg.train_dataloader.dataset.pipeline[1].crop_size == (32, 48)
    assert cfg.model.num_steps == 9 and cfg.num_steps == 9
    cfg = load_config(osp.join(ROOT, 'configs', 'reconstruction',
                               'wgse_resnet_cpu.py'), dict(crop_size=24))
    assert cfg.train_dataloader.dataset.crop_size == (24, 24)
    assert cfg.val_dataloader.dataset.crop_size == (64, 64)
    # a key beside the setting wins over it, as mmengine merges
    cfg = load_config(osp.join(ROOT, 'configs', 'pspnet_raw.py'), {
        'data_root': 'b', 'val_dataloader.dataset.data_root': 'a'})
    assert cfg.train_dataloader.dataset.data_root == 'b'
    assert cfg.val_dataloader.dataset.data_root == 'a'


def test_only_the_listed_fields_carry_t(tmp_path):
    """A transform of another package that takes ``num_steps`` (here a
    test-time augmentation's) is not a field of T; nor is an RGB model's
    ``in_channels`` without a spike data preprocessor."""
    child = _child(tmp_path, 'segformer_b0_raw.py', (
        'num_steps = 41\n'
        "test_dataloader = dict(dataset=dict(pipeline=[\n"
        "    dict(type='LoadSpikeFromFile', num_steps=129),\n"
        "    dict(type='OtherPackageTTA', num_steps=7)]))\n"))
    cfg = load_config(child)
    assert [step.num_steps for step in
            cfg.test_dataloader.dataset.pipeline] == [41, 7]
    rgb = Config(dict(num_steps=41, model=dict(
        data_preprocessor=dict(type='SegDataPreProcessor'),
        backbone=dict(in_channels=3))))
    assert apply_spike_settings(rgb) == {}
    assert rgb.model.backbone.in_channels == 3


@pytest.mark.parametrize('options, message', [
    (dict(num_steps=0), 'num_steps must be an integer >= 1'),
    (dict(num_steps='many'), 'num_steps must be an integer >= 1'),
    (dict(crop_size='abc'), r"crop_size must be .*\(h, w\).*got 'abc'"),
    (dict(crop_size='1,2,3'), r'crop_size must be .*\(h, w\)'),
    (dict(data_root=''), 'data_root must be a path'),
])
def test_bad_command_line_values_are_named(options, message):
    with pytest.raises(SpikeSettingsError, match=message):
        load_config(osp.join(ROOT, 'configs', 'pspnet_raw.py'), options)


@pytest.mark.parametrize('name, error, message', [
    ('missing.py', FileNotFoundError, 'no such config file'),
    ('clip.npy', ValueError, r'not a config file \(expected one of \.py, '
     r'\.json, \.yaml, \.yml\)')])
def test_a_file_that_is_no_config_is_named(tmp_path, name, error, message):
    """Before mmengine reads it (whose OSError named neither the file nor
    what it expected)."""
    (tmp_path / 'clip.npy').write_bytes(b'\x93NUMPY')
    path = str(tmp_path / name)
    with pytest.raises(error, match=f'{path}: {message}'):
        load_config(path)


def _spike_model(tmp_path, base, body=''):
    """A user's config for MMSeg's model base ``base`` by the documented
    recipe, without the ``in_channels`` line."""
    path = tmp_path / 'mine.py'
    path.write_text(
        f"_base_ = ['mmseg::_base_/models/{base}.py',\n"
        f"          {osp.join(ROOT, 'configs/_base_/datasets/spike_cityscapes.py')!r}]\n"  # noqa: E501
        "model = dict(data_preprocessor=dict(\n"
        "    _delete_=True, **_base_.spike_data_preprocessor))\n" + body)
    return str(path)


@pytest.mark.parametrize('base, stems', [
    # in_channels=3 in MMSeg's base: replaced
    ('fcn_unet_s5-d16', {'model.backbone.in_channels': 3}),
    # not in the config, BiSeNetV2 takes it: added
    ('bisenetv2', {'model.backbone.in_channels': None}),
    # not in the config, ResNetV1c takes it through **kwargs: added
    ('pspnet_r50-d8', {'model.backbone.in_channels': None}),
    # the stem of STDC's context path is its nested backbone's
    ('stdc', {'model.backbone.backbone_cfg.in_channels': 3}),
    # BiSeNetV1: its spatial path and its context path's ResNet
    ('bisenetv1_r18-d32', {'model.backbone.in_channels': 3,
                           'model.backbone.backbone_cfg.in_channels': 3}),
])
def test_t_reaches_the_stem_wherever_the_backbone_keeps_it(
        tmp_path, base, stems):
    cfg = Config.fromfile(_spike_model(tmp_path, base))
    changed = apply_spike_settings(cfg, dict(num_steps=41))
    assert {k: v for k, v in changed.items() if 'in_channels' in k} == stems
    for path in stems:
        node = cfg
        for part in path.split('.'):
            node = node[part]
        assert node == 41


def test_a_backbone_without_in_channels_is_left_to_the_start_up_check(
        tmp_path):
    """MobileNetV3 hard-codes three input channels: nothing to set."""
    cfg = Config.fromfile(_spike_model(tmp_path, 'lraspp_m-v3-d8'))
    changed = apply_spike_settings(cfg, dict(num_steps=41))
    assert 'in_channels' not in cfg.model.backbone
    assert not any('in_channels' in path for path in changed)
