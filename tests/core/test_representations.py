"""The classical representations (TFP, TFI, mean filters) against values
computed by hand and against direct loop implementations."""
import os.path as osp

import pytest
import torch

import wgse_mmseg

wgse_mmseg.register_all_modules()  # before MMSeg: these tests build from it

from mmseg.registry import MODELS  # noqa: E402
from wgse_mmseg.utils.config import load_config  # noqa: E402
from wgse_mmseg.core.representations import (  # noqa: E402
    TFI, TFP, SpatialMeanFilter, TemporalMeanFilter)

pytestmark = pytest.mark.usefixtures('single_thread')

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
NAMES = ['TFP', 'TFI', 'SpatialMeanFilter', 'TemporalMeanFilter']
CLASSES = dict(TFP=TFP, TFI=TFI, SpatialMeanFilter=SpatialMeanFilter,
               TemporalMeanFilter=TemporalMeanFilter)


def stream(*pixels, num_steps):
    """``(1, T, 1, len(pixels))`` with spikes at the listed steps."""
    spikes = torch.zeros(1, num_steps, 1, len(pixels))
    for index, steps in enumerate(pixels):
        spikes[0, list(steps), 0, index] = 1
    return spikes


def random_spikes(shape, seed=0, p=0.3):
    generator = torch.Generator().manual_seed(seed)
    return (torch.rand(shape, generator=generator) < p).float()


def loop_temporal_mean(spikes, window):
    out = torch.empty_like(spikes)
    num_steps, half = spikes.shape[1], window // 2
    for t in range(num_steps):
        lo, hi = max(0, t - half), min(num_steps, t + half + 1)
        out[:, t] = spikes[:, lo:hi].mean(dim=1)
    return out


def loop_spatial_mean(spikes, size):
    out = torch.empty_like(spikes)
    height, width, half = spikes.shape[2], spikes.shape[3], size // 2
    for y in range(height):
        for x in range(width):
            patch = spikes[:, :, max(0, y - half):y + half + 1,
                           max(0, x - half):x + half + 1]
            out[:, :, y, x] = patch.mean(dim=(2, 3))
    return out


@pytest.mark.parametrize('name', NAMES)
def test_registered_parameter_free_and_shape_preserving(name):
    module = MODELS.build(dict(type=name))
    assert sum(p.numel() for p in module.parameters()) == 0
    spikes = random_spikes((2, 7, 5, 6))
    out = module(spikes)
    assert out.shape == spikes.shape and out.dtype == torch.float32
    assert torch.isfinite(out).all()


def test_tfp_by_hand():
    # spikes at steps 0, 3, 4, 6 of T=7; window 3, cut at the ends
    out = TFP(window=3)(stream([0, 3, 4, 6], num_steps=7))[0, :, 0, 0]
    expected = torch.tensor([1 / 2, 1 / 3, 1 / 3, 2 / 3, 2 / 3, 2 / 3, 1 / 2])
    torch.testing.assert_close(out, expected)


@pytest.mark.parametrize('window', [1, 3, 5, 9, 15])
def test_temporal_mean_matches_loop_and_tfp_is_the_same_operator(window):
    spikes = random_spikes((2, 9, 3, 4), seed=window)
    expected = loop_temporal_mean(spikes, window)
    torch.testing.assert_close(TemporalMeanFilter(window)(spikes), expected)
    torch.testing.assert_close(TFP(window=window)(spikes), expected)


def test_temporal_mean_of_a_periodic_stream_is_its_rate_inside():
    spikes = stream(range(0, 40, 4), num_steps=40)  # rate 1/4
    out = TFP(window=9)(spikes)[0, 4:-4, 0, 0]
    # a 9-step window holds 2 or 3 spikes of a period-4 stream
    assert ((out - 0.25).abs() <= 1 / 9 + 1e-6).all()
    out = TFP(window=17)(spikes)[0, 8:-8, 0, 0]
    assert ((out - 0.25).abs() <= 1 / 17 + 1e-6).all()


@pytest.mark.parametrize('size', [1, 3, 5])
def test_spatial_mean_matches_loop(size):
    spikes = random_spikes((2, 3, 5, 7), seed=size)
    torch.testing.assert_close(SpatialMeanFilter(size)(spikes),
                               loop_spatial_mean(spikes, size))


def test_spatial_mean_by_hand():
    frame = torch.tensor([[1., 0., 0.], [0., 0., 0.], [0., 0., 1.]])
    out = SpatialMeanFilter(3)(frame.view(1, 1, 3, 3))[0, 0]
    expected = torch.tensor([[1 / 4, 1 / 6, 0.], [1 / 6, 2 / 9, 1 / 6],
                             [0., 1 / 6, 1 / 4]])
    torch.testing.assert_close(out, expected)


@pytest.mark.parametrize('period, phase', [(1, 0), (2, 0), (2, 1), (3, 1),
                                           (5, 4), (8, 0), (8, 3)])
def test_tfi_of_a_periodic_stream_is_its_rate_everywhere(period, phase):
    num_steps = 41
    spikes = stream(range(phase, num_steps, period), num_steps=num_steps)
    out = TFI()(spikes)
    torch.testing.assert_close(out, torch.full_like(out, 1 / period))


def test_tfi_by_hand():
    # spikes at 1, 4, 6 of T=9: intervals 3 then 2; before the first spike
    # the first interval stands in, from the last spike on the last one
    out = TFI()(stream([1, 4, 6], num_steps=9))[0, :, 0, 0]
    expected = torch.tensor([1 / 3] * 4 + [1 / 2] * 5)
    torch.testing.assert_close(out, expected)


def test_tfi_with_fewer_than_two_spikes_is_count_over_t():
    out = TFI()(stream([], [5], [0], [8], num_steps=9))[0, :, 0]
    torch.testing.assert_close(out[:, 0], torch.zeros(9))
    for pixel in (1, 2, 3):
        torch.testing.assert_close(out[:, pixel], torch.full((9, ), 1 / 9))


def test_tfi_pixels_are_independent():
    spikes = random_spikes((3, 13, 4, 5), seed=3)
    out = TFI()(spikes)
    for b, y, x in [(0, 0, 0), (1, 2, 3), (2, 3, 4)]:
        single = TFI()(spikes[b:b + 1, :, y:y + 1, x:x + 1])
        torch.testing.assert_close(out[b:b + 1, :, y:y + 1, x:x + 1], single)


def test_tfi_rejects_non_binary_input():
    spikes = torch.zeros(1, 5, 2, 2)
    spikes[0, 2, 1, 1] = 0.5
    with pytest.raises(ValueError, match='binary.*0.5'):
        TFI()(spikes)


@pytest.mark.parametrize('value', [float('nan'), float('inf'),
                                   float('-inf')])
@pytest.mark.parametrize('name', NAMES)
def test_non_finite_input_is_the_same_error_as_wgse(name, value):
    """NaN and Inf: a ValueError naming the module, the argument and the
    count, as WGSE gives on every backend (TFP and the mean filters used to
    spread a NaN along their cumulative sums; TFI called it non-binary)."""
    spikes = torch.zeros(2, 7, 3, 3, dtype=torch.float64)
    spikes[0, 0, 0, 0] = spikes[1, 6, 2, 2] = value
    nan = 2 if value != value else 0
    with pytest.raises(ValueError, match=(
            rf'^{name}: spikes holds 2 non-finite value\(s\) of 126 '
            rf'\({nan} NaN, {2 - nan} \+-Inf\)')):
        CLASSES[name]()(spikes)


@pytest.mark.parametrize('name', NAMES)
def test_single_step_and_window_longer_than_t(name):
    module = MODELS.build(dict(type=name))
    out = module(torch.ones(1, 1, 3, 3))
    torch.testing.assert_close(out, torch.ones(1, 1, 3, 3))


def test_window_longer_than_t_averages_the_whole_stream():
    spikes = random_spikes((1, 5, 2, 2), seed=4)
    torch.testing.assert_close(TFP(window=11)(spikes),
                               spikes.mean(1, keepdim=True).expand(-1, 5, -1,
                                                                   -1))


@pytest.mark.parametrize('name', NAMES)
def test_dtypes(name):
    module = MODELS.build(dict(type=name))
    spikes = random_spikes((1, 6, 3, 3))
    assert module(spikes.double()).dtype == torch.float64
    assert module(spikes.to(torch.uint8)).dtype == torch.float32
    with torch.autocast('cpu', dtype=torch.bfloat16):
        out = module(spikes.bfloat16())
    assert out.dtype == torch.float32
    torch.testing.assert_close(out, module(spikes))


@pytest.mark.parametrize('name', NAMES)
def test_wrong_shapes_are_named(name):
    module = MODELS.build(dict(type=name))
    with pytest.raises(ValueError, match=r'\(B, T, H, W\).*\(6, 3, 3\)'):
        module(torch.zeros(6, 3, 3))
    with pytest.raises(ValueError, match=r'T >= 1'):
        module(torch.zeros(1, 0, 3, 3))


@pytest.mark.parametrize('module, kwargs', [
    (TFP, dict(window=4)), (TFP, dict(window=0)),
    (TemporalMeanFilter, dict(kernel_size=2)),
    (SpatialMeanFilter, dict(kernel_size=-3)),
    (SpatialMeanFilter, dict(kernel_size=2.0)),
])
def test_even_or_invalid_windows_are_rejected(module, kwargs):
    with pytest.raises(ValueError, match='must be an odd integer >= 1'):
        module(**kwargs)


@pytest.mark.parametrize('enhancer', [
    dict(type='TFP', window=5), dict(type='TFI'),
    dict(type='SpatialMeanFilter', kernel_size=3),
    dict(type='TemporalMeanFilter', kernel_size=3)
])
def test_selectable_in_a_config_like_wgse(enhancer):
    options = {'num_steps': 9, 'model.data_preprocessor.enhancer': None}
    cfg = load_config(osp.join(ROOT, 'configs', 'segformer_b0_raw.py'),
                      options)
    cfg.model.data_preprocessor.enhancer = enhancer
    model = MODELS.build(cfg.model)
    built = model.data_preprocessor.enhancer
    assert type(built).__name__ == enhancer['type']
    data = dict(inputs=[random_spikes((9, 32, 32)).to(torch.uint8)],
                data_samples=None)
    raw = data['inputs'][0][None].float()
    batch = model.data_preprocessor(data)['inputs']  # batched and enhanced
    assert batch.shape == (1, 9, 32, 32)
    torch.testing.assert_close(batch, built(raw))
    seen = []  # what the backbone receives: the enhancer's output
    model.backbone.register_forward_pre_hook(
        lambda module, args: seen.append(args[0]))
    model.eval()
    with torch.no_grad():
        model(batch, mode='tensor')
    torch.testing.assert_close(seen[0], built(raw))
