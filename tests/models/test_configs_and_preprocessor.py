"""The four main configs build and train a step; the preprocessor's
contract."""
import os.path as osp

import numpy as np
import pytest
import torch
from mmengine.structures import PixelData

import wgse_mmseg
from mmseg.registry import MODELS
from mmseg.structures import SegDataSample
from wgse_mmseg.utils.config import load_config

wgse_mmseg.register_all_modules()  # before mmseg builds anything

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
PSPNET_WGSE = 'pspnet_wgse'
PSPNET_RAW = 'pspnet_raw'
SEGFORMER_WGSE = 'segformer_b0_wgse'
SEGFORMER_RAW = 'segformer_b0_raw'
MAIN_CONFIGS = [PSPNET_WGSE, PSPNET_RAW, SEGFORMER_WGSE,
                SEGFORMER_RAW]
WGSE_PARAMETERS = 19974  # db8, 5 levels, kernel 3, 32 hidden channels


def config_path(name):
    return osp.join(ROOT, 'configs', f'{name}.py')


def spike_batch(num_steps, height, width, batch=2, seed=0):
    generator = torch.Generator().manual_seed(seed)
    inputs, samples = [], []
    for _ in range(batch):
        inputs.append((torch.rand(num_steps, height, width,
                                  generator=generator) < 0.3).to(torch.uint8))
        label = torch.randint(0, 19, (1, height, width), generator=generator)
        sample = SegDataSample(gt_sem_seg=PixelData(data=label))
        sample.set_metainfo(dict(img_shape=(height, width),
                                 ori_shape=(height, width),
                                 pad_shape=(height, width)))
        samples.append(sample)
    return dict(inputs=inputs, data_samples=samples)


def build(name, **options):
    cfg = load_config(config_path(name), options)
    return cfg, MODELS.build(cfg.model)


def count(model):
    return sum(p.numel() for p in model.parameters())


@pytest.mark.parametrize('name', MAIN_CONFIGS)
def test_config_defaults_are_the_papers(name):
    cfg = load_config(config_path(name))
    assert cfg.num_steps == 129
    assert tuple(cfg.crop_size) == (256, 512)
    assert cfg.model.backbone.in_channels == 129
    assert cfg.model.data_preprocessor.num_steps == 129
    assert cfg.train_dataloader.batch_size == 4
    assert cfg.optim_wrapper.optimizer.type == 'AdamW'
    expected_lr = 1e-3 if name.startswith('pspnet') else 2e-4
    assert cfg.optim_wrapper.optimizer.lr == expected_lr
    assert cfg.model.decode_head.sampler.type == 'OHEMPixelSampler'
    assert cfg.model.decode_head.loss_decode.type == 'CrossEntropyLoss'
    assert cfg.param_scheduler[0].end == 10  # 10-epoch warm-up
    has_wgse = cfg.model.data_preprocessor.enhancer is not None
    assert has_wgse == name.endswith('_wgse')
    assert cfg.model.get('pretrained') is None
    assert tuple(cfg.custom_imports.imports) == ('wgse_mmseg.mmseg_layer', )


def test_pspnet_starts_wgse_at_the_low_pass_approximation():
    """The recipe docs/wgse_vs_tfp.md found to put WGSE level with TFP in
    front of PSPNet; SegFormer-B0 keeps the paper's random start, and the
    raw-spike config inherits no enhancer."""
    paper = dict(type='WGSE', dim=1, wavelet='db8', level=5, mode='zero',
                 kernel_size=3, hidden_channels=32)
    pspnet = load_config(config_path(PSPNET_WGSE))
    assert pspnet.model.data_preprocessor.enhancer == dict(paper,
                                                           init='lowpass')
    segformer = load_config(config_path(SEGFORMER_WGSE))
    assert segformer.model.data_preprocessor.enhancer == paper
    raw = load_config(config_path(PSPNET_RAW))
    assert raw.model.data_preprocessor.enhancer is None


def test_spike_settings_override_every_dependent_field():
    cfg = load_config(config_path(PSPNET_WGSE),
                      dict(num_steps=41, crop_size='64,128',
                           data_root='/elsewhere'))
    assert cfg.model.backbone.in_channels == 41
    assert cfg.model.data_preprocessor.num_steps == 41
    assert tuple(cfg.model.data_preprocessor.size) == (64, 128)
    assert cfg.train_dataloader.dataset.pipeline[0].num_steps == 41
    assert tuple(cfg.train_dataloader.dataset.pipeline[2].crop_size) == (
        64, 128)
    assert cfg.val_dataloader.dataset.data_root == '/elsewhere'
    # and the override did not leak into the next load
    assert load_config(config_path(PSPNET_WGSE)).num_steps == 129


@pytest.mark.parametrize('wgse_name, raw_name', [
    (PSPNET_WGSE, PSPNET_RAW), (SEGFORMER_WGSE, SEGFORMER_RAW)])
def test_wgse_twin_adds_exactly_the_wgse_parameters(wgse_name, raw_name):
    _, with_wgse = build(wgse_name, num_steps=9)
    _, raw = build(raw_name, num_steps=9)
    assert count(with_wgse) - count(raw) == WGSE_PARAMETERS


@pytest.mark.parametrize('name', MAIN_CONFIGS)
def test_forward_backward_on_a_spike_batch(name):
    torch.manual_seed(0)
    _, model = build(name, num_steps=9, crop_size='32,64')
    model.train()
    data = model.data_preprocessor(spike_batch(9, 32, 64), training=True)
    assert data['inputs'].shape == (2, 9, 32, 64)
    assert data['inputs'].dtype == torch.float32
    losses = model.loss(data['inputs'], data['data_samples'])
    total = sum(v for k, v in losses.items() if 'loss' in k)
    assert torch.isfinite(total)
    total.backward()
    grads = [p.grad for p in model.parameters() if p.grad is not None]
    assert grads and all(torch.isfinite(g).all() for g in grads)
    if name.endswith('_wgse'):
        enhancer = model.data_preprocessor.enhancer
        assert any(p.grad is not None and p.grad.abs().sum() > 0
                   for p in enhancer.parameters())


def test_preprocessor_pads_spikes_with_zero_and_labels_with_ignore():
    preprocessor = MODELS.build(
        dict(type='SpikeSegDataPreProcessor', num_steps=5, size=(8, 12)))
    batch = spike_batch(5, 6, 10, batch=1)
    batch['inputs'][0].fill_(1)
    out = preprocessor(batch, training=True)
    inputs, label = out['inputs'], out['data_samples'][0].gt_sem_seg.data
    assert inputs.shape == (1, 5, 8, 12)
    assert inputs[..., :6, :10].eq(1).all()
    assert inputs[..., 6:, :].eq(0).all() and inputs[..., :, 10:].eq(0).all()
    assert label[..., 6:, :].eq(255).all() and label[..., :, 10:].eq(255).all()


def test_mismatched_num_steps_names_both_numbers_and_the_file():
    _, model = build(SEGFORMER_WGSE, num_steps=41)
    batch = spike_batch(17, 16, 16, batch=1)
    batch['data_samples'][0].set_metainfo(dict(img_path='clip_0001_spike.spk'))
    with pytest.raises(ValueError) as err:
        model.data_preprocessor(batch, training=True)
    message = str(err.value)
    assert 'T=17' in message and 'T=41' in message
    assert 'clip_0001_spike.spk' in message


@pytest.mark.parametrize('name', MAIN_CONFIGS)
def test_labels_outside_the_classes_name_the_file_and_values(name):
    cfg, model = build(name, num_steps=9, crop_size='16,16')
    assert cfg.model.data_preprocessor.num_classes == 19
    batch = spike_batch(9, 16, 16, batch=2)
    label = batch['data_samples'][1].gt_sem_seg.data
    label[0, 0, :3] = torch.tensor([255, 19, 33])  # 255 ignored; 19, 33 not
    batch['data_samples'][1].set_metainfo(
        dict(seg_map_path='aachen_000000_000019_gtFine_labelIds.png'))
    with pytest.raises(ValueError) as err:
        model.data_preprocessor(batch, training=True)
    message = str(err.value)
    assert 'aachen_000000_000019_gtFine_labelIds.png' in message
    assert '[19, 33]' in message and '19 classes' in message


def test_labels_of_the_classes_and_ignore_index_pass():
    preprocessor = MODELS.build(
        dict(type='SpikeSegDataPreProcessor', num_steps=5, num_classes=19,
             size=(4, 6)))
    batch = spike_batch(5, 4, 6, batch=1)
    label = batch['data_samples'][0].gt_sem_seg.data
    label.view(-1)[:20] = torch.tensor(list(range(19)) + [255])
    out = preprocessor(batch, training=True)
    assert torch.equal(out['data_samples'][0].gt_sem_seg.data, label)


def test_paramwise_cfg_gives_the_enhancer_its_own_learning_rate():
    """The enhancer's parameters are the model's
    (``data_preprocessor.enhancer.*``), so MMSeg's ``paramwise_cfg`` reaches
    them like any other."""
    from mmengine.optim import build_optim_wrapper
    cfg, model = build(SEGFORMER_WGSE, num_steps=9)
    optim_wrapper = dict(cfg.optim_wrapper, paramwise_cfg=dict(
        custom_keys={'data_preprocessor.enhancer': dict(lr_mult=10.0)}))
    optimizer = build_optim_wrapper(model, optim_wrapper).optimizer
    names = {id(p): n for n, p in model.named_parameters()}
    rates = {names[id(p)]: group['lr'] for group in optimizer.param_groups
             for p in group['params']}
    base = cfg.optim_wrapper.optimizer.lr
    enhancer = [n for n in rates if n.startswith('data_preprocessor.enhancer')]
    assert len(enhancer) == len(list(
        model.data_preprocessor.enhancer.parameters()))
    assert all(rates[n] == pytest.approx(10 * base) for n in enhancer)
    assert all(rates[n] == pytest.approx(base) for n in rates
               if n not in enhancer)


def test_inference_model_takes_a_spike_file(tmp_path):
    from mmseg.apis import inference_model, init_model

    from wgse_mmseg.fileio.spike_files import save_spikes
    cfg = load_config(config_path(SEGFORMER_WGSE),
                      dict(num_steps=9))
    path = str(tmp_path / 'clip.npy')
    save_spikes(path, (np.random.default_rng(0).random((9, 32, 64)) <
                       0.3).astype(np.uint8))
    result = inference_model(init_model(cfg, None, device='cpu'), path)
    assert result.pred_sem_seg.data.shape == (1, 32, 64)
    assert result.img_path == path
