"""A full MMSeg config (its model and its own data loaders, no
``_base_/models`` file) with the spike dataset: the model trains on spikes
and the result is a config file the tools read back."""
import pytest
from mmengine.registry import init_default_scope

import wgse_mmseg
from mmseg.registry import MODELS
from wgse_mmseg.utils.cross_checks import check_training_fits

wgse_mmseg.register_all_modules()


@pytest.mark.parametrize('config', [
    'mmseg::pidnet/pidnet-s_2xb6-120k_1024x1024-cityscapes.py',
    'mmseg::ddrnet/ddrnet_23-slim_in1k-pre_2xb6-120k_cityscapes-1024x1024.py',
])
def test_a_full_config_takes_the_spike_dataset(tmp_path, config):
    cfg = wgse_mmseg.spike_config(config, enhancer=dict(type='TFP'),
                                  cfg_options=dict(num_steps=7,
                                                   crop_size=(64, 64)))
    assert cfg.train_dataloader.dataset.type == 'SpikeCityscapesDataset'
    assert cfg.model.data_preprocessor.type == 'SpikeSegDataPreProcessor'
    assert cfg.model.data_preprocessor.enhancer == dict(type='TFP')
    assert cfg.model.backbone.in_channels == 7
    assert cfg.tta_pipeline[0].num_steps == 7  # the spike set's flips
    init_default_scope('mmseg')
    model = MODELS.build(cfg.model)
    check_training_fits(cfg, model)
    path = tmp_path / 'spikes.py'
    cfg.dump(str(path))
    again = wgse_mmseg.load_config(str(path))
    assert again.model.to_dict() == cfg.model.to_dict()
    assert again.num_steps == 7
