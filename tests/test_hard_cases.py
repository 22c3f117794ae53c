"""Hard cases stay numerically stable.

* OHEM cross-entropy (the configs' decode-head loss) with every pixel
  ignored, with one valid pixel, with saturated logits; labels outside the
  classes fail instead of giving a loss.
* Empty (all-zero) and saturated (all-one) spike streams through every
  enhancer and both models, in float32 and under autocast, forward and
  backward: finite outputs, losses and gradients.

Autocast: every enhancer is tested under CPU autocast to bfloat16 and to
float16 (both work with torch 2.13); the two models under CPU autocast to
bfloat16, and to float16 where CUDA is present. Without native bfloat16
kernels a PSPNet step under CPU autocast takes 10-30 s on a 2-core machine,
so the autocast model test uses one batch holding an empty and a saturated
stream.
"""
import os.path as osp

import pytest
import torch
from mmengine.structures import PixelData

from mmseg.registry import MODELS
from mmseg.structures import SegDataSample
from wgse_mmseg.utils.config import load_config

pytestmark = pytest.mark.usefixtures('single_thread')

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
NUM_CLASSES, IGNORE = 19, 255
NUM_STEPS, SIZE = 9, (32, 32)
ENHANCERS = {
    'wgse1d': dict(type='WGSE', dim=1),
    'wgse2d': dict(type='WGSE', dim=2),
    'wgse3d': dict(type='WGSE', dim=3),
    'wgse_long': dict(type='WGSE', num_blocks=2, wavelet='haar', level=3),
    'trcnn': dict(type='WGSE', wavelet=None),
    'tfp': dict(type='TFP', window=5),
    'tfi': dict(type='TFI'),
    'mean_spatial': dict(type='SpatialMeanFilter', kernel_size=3),
    'mean_temporal': dict(type='TemporalMeanFilter', kernel_size=3),
}
STREAMS = {'empty': 0.0, 'saturated': 1.0}
CPU_AUTOCAST = [None, torch.bfloat16, torch.float16]


RAW_CONFIGS = {
    'segformer_b0': 'segformer_b0_raw',
    'pspnet': 'pspnet_raw'}


def config(model):
    return load_config(osp.join(ROOT, 'configs', f'{RAW_CONFIGS[model]}.py'),
                       dict(num_steps=NUM_STEPS,
                            crop_size=','.join(map(str, SIZE))))


def samples(labels):
    """Data samples carrying ``labels`` ``(B, H, W)`` as ground truth."""
    out = []
    for label in labels:
        sample = SegDataSample(gt_sem_seg=PixelData(data=label[None]))
        shape = tuple(label.shape)
        sample.set_metainfo(dict(img_shape=shape, ori_shape=shape,
                                 pad_shape=shape))
        out.append(sample)
    return out


def assert_finite_grads(module):
    grads = [p.grad for p in module.parameters() if p.grad is not None]
    assert all(torch.isfinite(g).all() for g in grads)
    return grads


# ------------------------------------------------------------ OHEM loss
@pytest.fixture(scope='module', params=['segformer_b0', 'pspnet'])
def decode_head(request):
    head_cfg = config(request.param).model.decode_head
    assert head_cfg.sampler.type == 'OHEMPixelSampler'
    return MODELS.build(head_cfg)


def head_loss(head, logits, labels, dtype=None):
    logits = logits.clone().requires_grad_(True)
    with torch.autocast('cpu', dtype=dtype or torch.bfloat16,
                        enabled=dtype is not None):
        losses = head.loss_by_feat(logits, samples(labels))
    loss = losses['loss_ce']
    loss.backward()
    return loss, logits.grad


def test_ohem_with_every_pixel_ignored(decode_head):
    logits = torch.randn(2, NUM_CLASSES, 8, 8)
    labels = torch.full((2, 32, 32), IGNORE)
    loss, grad = head_loss(decode_head, logits, labels)
    assert torch.isfinite(loss) and loss == 0
    assert torch.isfinite(grad).all() and (grad == 0).all()


def test_ohem_with_one_valid_pixel(decode_head):
    torch.manual_seed(0)
    logits = torch.randn(2, NUM_CLASSES, 8, 8)
    labels = torch.full((2, 32, 32), IGNORE)
    labels[1, 5, 7] = 3
    loss, grad = head_loss(decode_head, logits, labels)
    assert torch.isfinite(loss) and loss > 0
    assert torch.isfinite(grad).all() and grad.abs().sum() > 0


@pytest.mark.parametrize('dtype', [None, torch.bfloat16])
@pytest.mark.parametrize('agree', [True, False])
def test_ohem_with_saturated_logits(decode_head, agree, dtype):
    # softmax saturates to exact 0/1: confident and right (OHEM keeps no
    # pixel: loss 0) or confident and wrong (loss ~1e4, still finite)
    labels = torch.randint(0, NUM_CLASSES, (2, 8, 8),
                           generator=torch.Generator().manual_seed(1))
    labels[0, 0, :] = IGNORE
    target = labels.clamp(max=NUM_CLASSES - 1)
    if not agree:
        target = (target + 1) % NUM_CLASSES
    logits = torch.full((2, NUM_CLASSES, 8, 8), -1e4)
    logits.scatter_(1, target[:, None], 1e4)
    loss, grad = head_loss(decode_head, logits, labels, dtype)
    assert torch.isfinite(loss) and torch.isfinite(grad).all()
    if agree:
        assert loss == 0
    else:
        assert loss > 1e3


@pytest.mark.parametrize('bad', [NUM_CLASSES, 254])
def test_labels_outside_the_classes_fail_instead_of_giving_a_loss(
        decode_head, bad):
    labels = torch.zeros(1, 8, 8, dtype=torch.long)
    labels[0, 2, 3] = bad
    with pytest.raises((IndexError, RuntimeError), match='out of bounds'):
        head_loss(decode_head, torch.randn(1, NUM_CLASSES, 8, 8), labels)


# --------------------------------------------- empty and saturated streams
@pytest.mark.parametrize('dtype', CPU_AUTOCAST)
@pytest.mark.parametrize('stream', STREAMS)
@pytest.mark.parametrize('name', ENHANCERS)
def test_enhancer_on_empty_and_saturated_streams(name, stream, dtype):
    torch.manual_seed(0)
    enhancer = MODELS.build(ENHANCERS[name])
    spikes = torch.full((2, NUM_STEPS, 4, 4), STREAMS[stream])
    with torch.autocast('cpu', dtype=dtype or torch.bfloat16,
                        enabled=dtype is not None):
        out = enhancer(spikes)
    assert out.shape == spikes.shape and torch.isfinite(out).all()
    if out.requires_grad:
        out.float().square().mean().backward()
        assert assert_finite_grads(enhancer)
    if name in ('tfp', 'tfi', 'mean_spatial', 'mean_temporal'):
        # a constant stream is its own rate: 0 or 1 everywhere
        torch.testing.assert_close(out, spikes)


@pytest.fixture(scope='module', params=['segformer_b0', 'pspnet'])
def segmentor(request):
    torch.manual_seed(0)
    return MODELS.build(config(request.param).model)


def spike_batch(values):
    """One ``(T, H, W)`` stream per value, each all that value, with random
    train-id labels."""
    generator = torch.Generator().manual_seed(0)
    labels = torch.randint(0, NUM_CLASSES, (len(values), *SIZE),
                           generator=generator)
    inputs = [torch.full((NUM_STEPS, *SIZE), v, dtype=torch.uint8)
              for v in values]
    return dict(inputs=inputs, data_samples=samples(labels))


def train_pass(model, enhancer, values, device='cpu', dtype=None):
    """Loss of one training forward and backward; checks it, the inputs
    the backbone saw and every gradient for finiteness."""
    model.data_preprocessor.enhancer = (None if enhancer is None else
                                        MODELS.build(enhancer))
    model.to(device).train()
    model.zero_grad(set_to_none=True)
    with torch.autocast(device, dtype=dtype or torch.bfloat16,
                        enabled=dtype is not None):
        data = model.data_preprocessor(spike_batch(values), training=True)
        assert torch.isfinite(data['inputs']).all()
        losses = model.loss(data['inputs'], data['data_samples'])
    loss = sum(v for k, v in losses.items() if 'loss' in k)
    assert torch.isfinite(loss), losses
    loss.backward()
    assert assert_finite_grads(model)
    return loss


@pytest.mark.parametrize('name', [None] + list(ENHANCERS))
def test_models_on_empty_and_saturated_streams(segmentor, name):
    train_pass(segmentor, ENHANCERS.get(name), [0, 1])


@pytest.mark.parametrize('value', [0, 1])
def test_models_on_a_batch_of_constant_streams(segmentor, value):
    # batch norm over a batch without any variation
    train_pass(segmentor, ENHANCERS['wgse1d'], [value, value])


def test_models_under_bfloat16_autocast(segmentor):
    train_pass(segmentor, ENHANCERS['wgse1d'], [0, 1], dtype=torch.bfloat16)


@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs CUDA')
@pytest.mark.parametrize('name', [None] + list(ENHANCERS))
def test_models_under_float16_autocast_on_cuda(segmentor, name):
    train_pass(segmentor, ENHANCERS.get(name), [0, 1], device='cuda',
               dtype=torch.float16)
    segmentor.cpu()


@pytest.mark.parametrize('name', ENHANCERS)
def test_enhancers_name_a_meaningless_shape(name):
    enhancer = MODELS.build(ENHANCERS[name])
    with pytest.raises(ValueError, match=r'\(B, T, H, W\)'):
        enhancer(torch.zeros(NUM_STEPS, 4, 4))


def test_every_enhancer_has_hard_cases():
    """The cases above cover the one list of enhancers, so a new one is
    tested here (add a config to ENHANCERS) and allowed in reconstruction
    checkpoints, by its registered name."""
    from wgse_mmseg.core.enhancers import ENHANCERS as CLASSES
    from wgse_mmseg.models.reconstruction import (RECONSTRUCTION_BUILDS,
                                                  SpikeReconstructor)
    names = {cls.__name__ for cls in CLASSES}
    assert {cfg['type'] for cfg in ENHANCERS.values()} == names
    assert all(MODELS.get(cls.__name__) is cls for cls in CLASSES)
    allowed = RECONSTRUCTION_BUILDS[SpikeReconstructor]['enhancer']
    assert set(allowed) == set(CLASSES)
