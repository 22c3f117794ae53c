"""T in one place: a child config that sets ``num_steps`` alone gets it in
every field built from it, with MMSeg's loader and with the project's."""
import os.path as osp

import pytest
from mmengine.config import Config
from mmengine.registry import RUNNERS

import wgse_mmseg
from wgse_mmseg.utils.config import load_config
from wgse_mmseg.utils.num_steps import NumStepsError, apply_num_steps

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
    assert apply_num_steps(cfg) == {
        'model.backbone.in_channels': 129,
        'model.data_preprocessor.num_steps': 129,
        **{f'{split}_dataloader.dataset.pipeline[0].num_steps': 129
           for split in ('train', 'val', 'test')}}
    assert _t_values(cfg) == dict(in_channels=41, preprocessor=41,
                                  loaders={41})
    assert apply_num_steps(cfg) == {}  # and once is enough
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
        'num_steps = 41\nmodel = dict(data_preprocessor=dict(num_steps=41))\n'))
    with pytest.raises(NumStepsError) as error:
        apply_num_steps(cfg)
    message = str(error.value)
    assert 'model.data_preprocessor.num_steps = 41' in message
    assert 'model.backbone.in_channels = 129' in message
    assert 'train_dataloader.dataset.pipeline[0].num_steps = 129' in message
    assert '--cfg-options num_steps=41' in message
    with pytest.raises(NumStepsError, match='must be an integer >= 1'):
        apply_num_steps(Config(dict(num_steps='41')))
    with pytest.raises(NumStepsError, match='must be an integer >= 1'):
        apply_num_steps(Config(dict(num_steps=0)))


def test_reconstruction_configs_follow_too(tmp_path):
    cfg = load_config(_child(tmp_path, 'reconstruction/wgse_resnet.py',
                             'num_steps = 21\n'))
    assert cfg.model.num_steps == 21
    assert cfg.train_dataloader.dataset.num_steps == 21
    assert cfg.test_dataloader.dataset.pipeline[0].num_steps == 21
