"""The spike simulator: closed forms of the base model, each effect's switch
and meaning, determinism, scenes and input errors."""
import json
import math
import re
import shutil

import cv2
import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from wgse_mmseg.core.constants import READOUT_HZ
from wgse_mmseg.core.simulation import (EFFECTS, fixed_point,
                                        frames_to_intensity, initial_charge,
                                        parse_effects, simulate_spikes)
from wgse_mmseg.core.simulation.camera_motion import (CameraMotion,
                                                      trajectory_source_maps)
from wgse_mmseg.core.simulation.effect import SensorEffect, SimulationContext
from wgse_mmseg.core.simulation.fixed_point import ONE, Integrator, quantise
from wgse_mmseg.core.simulation.interpolation import FlowLight
from wgse_mmseg.core.simulation.light import LinearLight
from wgse_mmseg.core.simulation.sensor import SensorMaps
from wgse_mmseg.core.simulation.warp import affine_grid
from wgse_mmseg.fileio.scene_files import read_scene_file
from wgse_mmseg.limits import check_allocation

pytestmark = pytest.mark.usefixtures('single_thread')


def _image(shape=(6, 7), seed=0):
    return np.random.default_rng(seed).integers(0, 256, (1, ) + shape,
                                                dtype=np.uint8)


def _video(count=3, shape=(6, 7), seed=0):
    return np.random.default_rng(seed).integers(0, 256, (count, ) + shape,
                                                dtype=np.uint8)


def _q0(frames, seed):
    """The initial charge in thresholds, ``(H, W)`` float64."""
    height, width = np.shape(frames)[1:3]
    charge = initial_charge(height * width, seed).numpy() / ONE
    return charge.reshape(height, width)


def _sequential(charge_per_step, q0):
    """Plain float64 integrate-and-fire, one step at a time."""
    charge = q0.copy()
    spikes = np.zeros(charge_per_step.shape, np.uint8)
    for step, a in enumerate(charge_per_step):
        charge += a
        fired = charge >= 1
        charge -= fired
        spikes[step] = fired
    return spikes


# ------------------------------------------------------------ closed forms
@given(value_seed=st.integers(0, 2**16), seed=st.integers(0, 2**31),
       steps=st.integers(1, 300), threshold=st.floats(1.0, 20.0),
       # 0 or a normal float32: the simulator refuses what float32 cannot
       # hold (its test: test_float32_overflow_and_underflow_are_refused)
       gain=st.just(0.0) | st.floats(1e-30, 1.0))
def test_constant_intensity_count_is_closed_form(value_seed, seed, steps,
                                                 threshold, gain):
    """Constant I: count = floor(q0 + T a), a = gain I / threshold < 1."""
    frames = _image(seed=value_seed)
    spikes, _ = simulate_spikes(frames, steps, threshold=threshold,
                                gain=gain, seed=seed)
    exact = _q0(frames, seed) + steps * gain * (frames[0] / 255) / threshold
    count = spikes.sum(0, dtype=np.int64)
    # Charge is resolved to 2**-24 thresholds: away from an integer by more
    # than that, the count is exactly the closed form.
    clear = np.abs(exact - np.round(exact)) > 1e-4
    np.testing.assert_array_equal(count[clear], np.floor(exact[clear]))
    assert np.all(np.abs(count - exact) < 1 + 1e-4)


@given(seed=st.integers(0, 2**31), steps=st.integers(1, 200),
       threshold=st.floats(1.0, 5.0))
def test_firing_rate_is_gain_intensity_over_threshold(seed, steps,
                                                      threshold):
    """The stated tolerance: |rate - a| <= 1 / T for every pixel."""
    frames = _image(seed=seed % 97)
    spikes, _ = simulate_spikes(frames, steps, threshold=threshold,
                                seed=seed)
    rate = spikes.mean(0)
    expected = frames[0] / 255 / threshold
    assert np.all(np.abs(rate - expected) <= 1 / steps + 1e-9)


def test_white_fires_one_over_threshold_per_step():
    frames = np.full((1, 4, 4), 255, np.uint8)
    spikes, _ = simulate_spikes(frames, 600, threshold=1 / 0.6, seed=1)
    assert abs(spikes.mean() - 0.6) <= 1 / 600


def test_still_image_equals_sequential_reference():
    frames = _image((9, 11), seed=3)
    spikes, _ = simulate_spikes(frames, 129, threshold=1 / 0.6, seed=5)
    a = np.broadcast_to(frames[0] / 255 * 0.6, (129, 9, 11))
    reference = _sequential(a, _q0(frames, 5))
    assert np.mean(spikes != reference) <= 1e-3


def test_video_is_linear_interpolation_of_frames():
    frames = _video(3, (9, 11), seed=4)
    steps = 129
    spikes, meta = simulate_spikes(frames, steps, threshold=1 / 0.6, seed=2)
    assert meta['resampling'] == 'linear'
    positions = np.linspace(0, 2, steps)
    index = np.minimum(positions.astype(int), 1)
    weight = (positions - index)[:, None, None]
    light = (1 - weight) * frames[index] / 255 + \
        weight * frames[index + 1] / 255
    reference = _sequential(light * 0.6, _q0(frames, 2))
    assert np.mean(spikes != reference) <= 1e-3
    exact = _q0(frames, 2) + (light * 0.6).sum(0)
    assert np.all(np.abs(spikes.sum(0) - exact) < 1 + 1e-3)


def test_frames_sit_on_evenly_spread_steps():
    """Frame n sits on step n (T - 1) / (N - 1): a pixel dark in every
    frame but the middle one fires only around the middle step."""
    frames = np.zeros((5, 1, 1), np.uint8)
    frames[2] = 255
    spikes, _ = simulate_spikes(frames, 9, threshold=0.5, seed=0)
    # steps 3, 4, 5 see 0.5, 1, 0.5 of white (positions 1.5, 2, 2.5)
    assert spikes[:3].sum() == 0 and spikes[6:].sum() == 0
    assert spikes[4, 0, 0] == 1


def test_saturation_fires_every_step():
    frames = np.full((1, 3, 3), 255, np.uint8)
    spikes, _ = simulate_spikes(frames, 50, threshold=0.4, seed=0)
    assert spikes.all()


def test_one_step_and_one_pixel():
    spikes, meta = simulate_spikes(np.ones((1, 1, 1)), 1, seed=0)
    assert spikes.shape == (1, 1, 1) and spikes[0, 0, 0] == 1
    assert meta['num_steps'] == 1


def test_colour_frames_use_luma():
    rgb = np.zeros((1, 2, 3, 3), np.uint8)
    rgb[0, 0, :, 0] = 255  # red row
    rgb[0, 1, :, 2] = 255  # blue row
    intensity = frames_to_intensity(rgb)
    assert intensity.dtype == torch.float64
    np.testing.assert_allclose(intensity[0, 0], 0.299)
    np.testing.assert_allclose(intensity[0, 1], 0.114)
    white = frames_to_intensity(np.ones((1, 2, 2, 3)))
    assert float(white.max()) <= 1.0


# ---------------------------------------------------------- the integrator
@given(seed=st.integers(0, 2**20), steps=st.integers(1, 32),
       level=st.floats(0.0, 0.999))
def test_integrator_closed_form_equals_per_step_sums(seed, steps, level):
    pixels = 50
    charge = torch.rand(pixels, generator=torch.Generator().manual_seed(
        seed)) * level
    linear, per_step = (torch.empty((steps, pixels), dtype=torch.uint8)
                        for _ in range(2))
    closed = Integrator(pixels, seed, 'cpu')
    closed.linear(closed.linear_charge(charge, None, 1),
                  np.zeros(steps, np.int64), linear)
    summed = Integrator(pixels, seed, 'cpu')
    summed.per_step(*quantise(charge.expand(steps, -1)), per_step)
    assert torch.equal(linear, per_step)
    assert torch.equal(closed.charge, summed.charge)


needs_kernel = pytest.mark.skipif(
    fixed_point.compiled_unavailable() is not None,
    reason=str(fixed_point.compiled_unavailable()))


@pytest.mark.skipif(shutil.which('cc') is None, reason='no C compiler')
def test_compiled_kernel_is_built_where_a_compiler_is():
    """``setup.py`` builds it as optional: a failed build must not go
    unnoticed where it could have succeeded."""
    assert fixed_point.compiled_unavailable() is None
    assert Integrator(4, 0, 'cpu').backend == 'compiled'  # what 'auto' picks


def _integrate_both_ways(pixels, seed, run):
    """``run(integrator, out)`` with the compiled kernel and with the torch
    path, tiles of 16 pixels side by side on two threads: both spikes and
    both carried charges."""
    results = []
    for backend in ('compiled', 'torch'):
        integrator = Integrator(pixels, seed, 'cpu', backend=backend)
        integrator.tile = 16
        out = torch.full((run.steps, pixels), 7, dtype=torch.uint8)
        threads = torch.get_num_threads()
        torch.set_num_threads(2)
        try:
            run(integrator, out)
        finally:
            torch.set_num_threads(threads)
        results.append((out, integrator.charge))
    return results


@needs_kernel
@given(seed=st.integers(0, 2**20), steps=st.integers(1, 150),
       pixels=st.integers(1, 70), still=st.booleans())
def test_compiled_linear_equals_torch_path(seed, steps, pixels, still):
    generator = torch.Generator().manual_seed(seed)
    first, last = torch.rand((2, pixels), generator=generator) * 0.999
    weights = np.random.default_rng(seed).integers(0, 8, steps)

    def run(integrator, out):
        integrator.linear(integrator.linear_charge(
            first, None if still else last, 7), weights, out)

    run.steps = steps
    (spikes, charge), (expected, expected_charge) = _integrate_both_ways(
        pixels, seed, run)
    assert torch.equal(spikes, expected)
    assert torch.equal(charge, expected_charge)


@needs_kernel
@given(seed=st.integers(0, 2**20), steps=st.integers(1, 80),
       pixels=st.integers(1, 70), top=st.floats(0.01, 3.0))
def test_compiled_per_step_equals_torch_path(seed, steps, pixels, top):
    """Including saturated steps (``top > 1``)."""
    charge = torch.rand((steps, pixels), generator=torch.Generator(
    ).manual_seed(seed)) * top

    def run(integrator, out):
        integrator.per_step(*quantise(charge), out)

    run.steps = steps
    (spikes, carried), (expected, expected_carried) = _integrate_both_ways(
        pixels, seed, run)
    assert torch.equal(spikes, expected)
    assert torch.equal(carried, expected_carried)


def test_quantise_keeps_the_fraction_of_saturated_steps():
    ints, saturated = quantise(torch.tensor([[0.25, 1.25, 3.5, 100.0]]))
    assert saturated
    assert ints.tolist() == [[ONE // 4, ONE + ONE // 4, ONE + ONE // 2,
                              ONE]]
    assert quantise(torch.tensor([[0.5]]))[1] is False


def test_saturated_steps_carry_their_fraction():
    """1.25 thresholds per step: a spike every step, and the fraction 0.25
    carries on, as with the charge taken modulo the threshold."""
    integrator = Integrator(1, 0, 'cpu')
    start = int(integrator.charge)
    out = torch.empty((4, 1), dtype=torch.uint8)
    integrator.per_step(*quantise(torch.full((4, 1), 1.25)), out)
    assert out.flatten().tolist() == [1, 1, 1, 1]
    assert int(integrator.charge) == (start + 4 * (ONE // 4)) % ONE


# ----------------------------------------------------------- effect switches
_STILL_EFFECTS = ['camera_motion', 'shot_noise', 'dark_current',
                  'fixed_pattern', 'hot_pixels', 'jitter']


def _effect_input(name):
    return _video(3, (8, 9)) if name == 'interpolation' else _image((8, 9))


@pytest.mark.parametrize('name', _STILL_EFFECTS + ['interpolation'])
def test_each_effect_changes_output_only_when_on(name):
    frames = _effect_input(name)
    params = dict(interpolation=dict(method='flow'),
                  hot_pixels=dict(fraction=0.2)).get(name, {})
    base, base_meta = simulate_spikes(frames, 64, threshold=1 / 0.6,
                                      seed=7)
    on, meta = simulate_spikes(frames, 64, threshold=1 / 0.6,
                               effects={name: params}, seed=7)
    assert not np.array_equal(on, base)
    assert base_meta['effects'] == {}
    full = {**EFFECTS[name].defaults, **params}
    if name == 'camera_motion':
        full['translation'] = [float(v) for v in full['translation']]
    assert meta['effects'] == {name: full}
    json.dumps(meta)  # the metadata is plain JSON


def test_all_off_equals_base_model_whatever_is_installed(monkeypatch):
    frames = _video(3, (8, 9))
    base, _ = simulate_spikes(frames, 40, threshold=1.5, seed=3)
    for effects in (None, {}):
        again, meta = simulate_spikes(frames, 40, threshold=1.5,
                                      effects=effects, seed=3)
        assert np.array_equal(again, base) and meta['effects'] == {}

    class Glare(SensorEffect):
        name = 'glare'
        defaults = dict(strength=1.0)

        def apply(self, maps, context):
            maps.add_dark_rate(torch.full((context.num_pixels, ), 1e4))

    monkeypatch.setitem(EFFECTS, 'glare', Glare)
    again, _ = simulate_spikes(frames, 40, threshold=1.5, seed=3)
    assert np.array_equal(again, base)
    glared, meta = simulate_spikes(frames, 40, threshold=1.5,
                                   effects={'glare': None}, seed=3)
    assert not np.array_equal(glared, base)
    assert meta['effects'] == {'glare': {'strength': 1.0}}


def test_linear_interpolation_is_the_base_resampling():
    frames = _video(4, (8, 9))
    base, base_meta = simulate_spikes(frames, 50, seed=1)
    named, meta = simulate_spikes(frames, 50, seed=1,
                                  effects={'interpolation': {}})
    assert np.array_equal(named, base)
    assert base_meta['resampling'] == meta['resampling'] == 'linear'
    assert meta['effects'] == {
        'interpolation': dict(method='linear', preset='medium')}


def test_meta_records_exactly_what_ran_in_canonical_order():
    effects = {'shot_noise': None, 'jitter': {'std': 0.01},
               'fixed_pattern': {}, 'camera_motion': {'per': 'clip',
                                                      'translation': [2, 1]}}
    _, meta = simulate_spikes(_image(), 20, effects=effects, seed=0)
    assert list(meta['effects']) == ['camera_motion', 'fixed_pattern',
                                     'jitter', 'shot_noise']
    assert meta['effects']['jitter'] == {'std': 0.01}
    assert meta['effects']['camera_motion'] == dict(
        translation=[2.0, 1.0], rotation=0.0, zoom=0.0, per='clip')
    assert meta['resampling'] == 'camera_motion'
    for key in ('model', 'num_steps', 'threshold', 'gain', 'seed',
                'readout_hz', 'num_frames', 'height', 'width'):
        assert key in meta


def test_effects_draw_from_their_own_streams():
    """Switching one effect on does not change another's draws."""
    context = SimulationContext(5, 6, 1, 10, 1.0, 1.0, READOUT_HZ, 3,
                                torch.device('cpu'))
    alone, both = SensorMaps(context), SensorMaps(context)
    for effect in parse_effects({'fixed_pattern': {}}):
        effect.apply(alone, context)
    for effect in parse_effects({'dark_current': {}, 'fixed_pattern': {}}):
        effect.apply(both, context)
    assert torch.equal(alone.gain, both.gain)
    assert torch.equal(alone.threshold, both.threshold)


# ---------------------------------------------------------- each effect
def _rate(spikes):
    return spikes.mean(0)


def test_dark_current_fires_in_the_dark():
    black = np.zeros((1, 10, 10), np.uint8)
    steps, rate = 2000, 400.0
    spikes, _ = simulate_spikes(
        black, steps, seed=0,
        effects={'dark_current': dict(rate=rate, std=0.0)})
    exact = _q0(black, 0) + steps * rate / READOUT_HZ
    np.testing.assert_array_equal(spikes.sum(0), np.floor(exact))
    assert simulate_spikes(black, steps, seed=0)[0].sum() == 0


def test_hot_pixels_fire_at_their_rate():
    black = np.zeros((1, 40, 50), np.uint8)
    spikes, _ = simulate_spikes(
        black, 400, seed=0,
        effects={'hot_pixels': dict(fraction=0.1, rate=8000.0)})
    rate = _rate(spikes)
    hot = rate > 0
    assert 0.07 < hot.mean() < 0.13
    np.testing.assert_allclose(rate[hot], 8000 / READOUT_HZ, atol=1 / 400)


def test_fixed_pattern_spreads_rates_by_its_stds():
    grey = np.full((1, 40, 40), 200, np.uint8)
    steps = 3000
    spikes, _ = simulate_spikes(
        grey, steps, seed=0,
        effects={'fixed_pattern': dict(gain_std=0.05, threshold_std=0.03)})
    rate = _rate(spikes)
    expected = 200 / 255
    assert abs(rate.mean() / expected - 1) < 0.01
    spread = rate.std() / rate.mean()
    assert abs(spread - math.hypot(0.05, 0.03)) < 0.008


def test_fixed_pattern_belongs_to_the_sensor():
    grey = np.full((1, 30, 30), 128, np.uint8)

    def rates(seed, sensor_seed=0):
        effects = {'fixed_pattern': dict(sensor_seed=sensor_seed)}
        return _rate(simulate_spikes(grey, 2000, seed=seed,
                                     effects=effects)[0])

    same = np.corrcoef(rates(1).ravel(), rates(2).ravel())[0, 1]
    new = np.corrcoef(rates(1, None).ravel(), rates(2, None).ravel())[0, 1]
    assert same > 0.8 and abs(new) < 0.3


def test_shot_noise_keeps_the_mean_and_adds_variance():
    grey = np.full((1, 30, 30), 100, np.uint8)
    steps = 400
    base, _ = simulate_spikes(grey, steps, seed=0)
    noisy, _ = simulate_spikes(grey, steps, seed=0,
                               effects={'shot_noise': dict(electrons=20)})
    expected = 100 / 255
    assert abs(noisy.mean() - expected) < 0.01
    assert noisy.sum(0).std() > 2 * base.sum(0).std()
    exact, _ = simulate_spikes(
        grey, steps, seed=0,
        effects={'shot_noise': dict(electrons=20, exact_below=1e9)})
    assert abs(exact.mean() - expected) < 0.01


def test_jitter_moves_spikes_but_keeps_the_charge():
    """Windows of 1 + e_t - e_(t-1) periods: over the clip only the two
    ends differ, by at most a * 1 threshold (a = 0.39, and no window
    reaches one threshold, so nothing saturates)."""
    grey = np.full((1, 30, 30), 100, np.uint8)
    base, _ = simulate_spikes(grey, 300, seed=0)
    jittered, _ = simulate_spikes(grey, 300, seed=0,
                                  effects={'jitter': dict(std=0.1)})
    assert np.mean(jittered != base) > 0.02
    assert np.all(np.abs(jittered.sum(0).astype(int) -
                         base.sum(0).astype(int)) <= 1)


def _context(steps, height=21, width=31, frames=1):
    return SimulationContext(height, width, frames, steps, 1.0, 1.0,
                             READOUT_HZ, 0, torch.device('cpu'))


def test_camera_motion_is_centred_and_translates():
    image = np.random.default_rng(0).random((1, 21, 31)).astype(np.float32)
    steps = 9
    effect = CameraMotion(dict(translation=[8, -4], per='clip'))
    light = effect.light(torch.from_numpy(image), _context(steps))
    middle = light.intensity(4, 5).view(21, 31).numpy()
    np.testing.assert_allclose(middle, image[0], atol=1e-5)
    last = light.intensity(8, 9).view(21, 31).numpy()
    # half the clip after the middle: content moved by (4, -2) pixels
    np.testing.assert_allclose(last[2:-4, 4:], image[0, 4:-2, :-4],
                               atol=1e-5)


def _source(light, step, x, y):
    """Where ``light`` shows, at pixel ``(x, y)`` of ``step``, the image."""
    maps = light.source_maps(step, step + 1)[0]
    return (maps[:, :2] @ torch.tensor([x, y], dtype=torch.float64) +
            maps[:, 2]).numpy()


def test_camera_motion_rotates_counter_clockwise_and_zooms():
    centre = np.array([15.0, 10.0])
    rotate = CameraMotion(dict(translation=[0, 0], rotation=180,
                               per='clip')).light(torch.zeros(1, 21, 31),
                                                  _context(3))
    # at +90 degrees, the pixel 5 above the centre shows what was 5 to the
    # right of it: content turned counter-clockwise on screen
    np.testing.assert_allclose(_source(rotate, 2, 15, 5), centre + [5, 0],
                               atol=1e-9)
    zoom = CameraMotion(dict(translation=[0, 0], zoom=0.2,
                             per='clip')).light(torch.zeros(1, 21, 31),
                                                _context(3))
    np.testing.assert_allclose(_source(zoom, 2, 26, 10),
                               centre + [11 / 1.1, 0], atol=1e-9)
    np.testing.assert_allclose(_source(zoom, 1, 26, 10), [26, 10])


@given(st.floats(-5, 5), st.floats(-3, 3), st.floats(-0.3, 0.3),
       st.floats(-0.05, 0.05), st.floats(-math.pi, math.pi),
       st.floats(0.5, 3), st.floats(-20, 20))
def test_trajectory_maps_invert_the_motion_model(dx, ax, rotation, zoom,
                                                 base_angle, base_scale,
                                                 tau):
    """Content at source point x appears where the module's forward model
    puts it: view_centre + s R(phi) (x - c) / base_scale + shift."""
    height, width, centre = 30, 50, np.array([70.0, 40.0])
    maps = trajectory_source_maps(
        torch.tensor([tau], dtype=torch.float64), (height, width),
        tuple(centre),
        translation=(dx, -dx / 2), acceleration=(ax, 0.5), rotation=rotation,
        zoom=zoom, base_angle=base_angle, base_scale=base_scale)[0].numpy()
    view = np.array([3.0, 27.0])
    source = maps[:, :2] @ view + maps[:, 2]
    phi, scale = base_angle + tau * rotation, 1 + tau * zoom
    # counter-clockwise on screen with y down
    turn = np.array([[math.cos(phi), math.sin(phi)],
                     [-math.sin(phi), math.cos(phi)]])
    shift = tau * np.array([dx, -dx / 2]) + tau**2 / 2 * np.array([ax, 0.5])
    back = (np.array([(width - 1) / 2, (height - 1) / 2]) +
            scale * turn @ (source - centre) / base_scale + shift)
    np.testing.assert_allclose(back, view, atol=1e-7)


def test_trajectory_maps_refuse_a_vanishing_zoom():
    with pytest.raises(ValueError, match='zoom=-0.1 shrinks the view'):
        trajectory_source_maps(torch.arange(-20.0, 21.0), (4, 4), (2, 2),
                               zoom=-0.1)


def test_camera_motion_per_second_uses_the_readout_rate():
    per_second = CameraMotion(dict(translation=[4000.0, 0.0])).light(
        torch.zeros(1, 5, 5), _context(5, 5, 5))
    per_clip = CameraMotion(dict(translation=[0.4, 0.0], per='clip')).light(
        torch.zeros(1, 5, 5), _context(5, 5, 5))
    # 5 steps at 40 kHz: 4 steps of 25 us = 100 us, 0.4 px at 4000 px/s
    assert torch.allclose(per_second.source_maps(0, 5),
                          per_clip.source_maps(0, 5))


def test_flow_interpolation_moves_content():
    """A texture moving 4 px between two frames: halfway, the flow light
    shows it moved 2 px, where a cross-fade shows a blur."""
    rng = np.random.default_rng(0)
    texture = cv2.GaussianBlur(rng.random((48, 84)).astype(np.float32),
                               (0, 0), 2)
    texture = (texture - texture.min()) / (texture.max() - texture.min())
    frames = torch.from_numpy(np.stack([texture[:, 4:68],
                                        texture[:, 0:64]]))
    truth = texture[:, 2:66]
    flow = FlowLight(frames, 9, 'medium').intensity(4, 5).view(48, 64)
    linear = LinearLight(frames, 9).intensity(4, 5).view(48, 64)
    inner = (slice(8, -8), slice(8, -8))
    flow_error = np.abs(flow.numpy() - truth)[inner].mean()
    linear_error = np.abs(linear.numpy() - truth)[inner].mean()
    assert flow_error < 0.2 * linear_error
    ends = FlowLight(frames, 9, 'fast')
    np.testing.assert_allclose(ends.intensity(0, 1).view(48, 64), frames[0],
                               atol=1e-5)


# --------------------------------------------------------------- determinism
_EVERYTHING = dict(interpolation=dict(method='flow', preset='fast'),
                   shot_noise={}, dark_current={}, fixed_pattern={},
                   hot_pixels=dict(fraction=0.05), jitter={})


@pytest.mark.parametrize('frames, effects', [
    (_image((8, 9)), None),
    (_video(3, (8, 9)), _EVERYTHING),
    (_image((8, 9)), {'camera_motion': {}, 'shot_noise': {}}),
], ids=['base', 'all-video', 'still-motion'])
def test_same_seed_same_stream(frames, effects):
    first, meta = simulate_spikes(frames, 40, effects=effects, seed=11)
    second, again = simulate_spikes(frames, 40, effects=effects, seed=11)
    assert np.array_equal(first, second) and meta == again
    other, _ = simulate_spikes(frames, 40, effects=effects, seed=12)
    assert not np.array_equal(first, other)


@needs_kernel
@pytest.mark.parametrize('frames, effects', [
    (_image((30, 41)), None),
    (_video(3, (30, 41)), None),
    (_video(3, (30, 41)), _EVERYTHING),
], ids=['still', 'video', 'all-video'])
def test_compiled_kernel_and_torch_path_simulate_the_same(frames, effects):
    compiled, meta = simulate_spikes(frames, 129, threshold=1 / 0.6,
                                     effects=effects, seed=5,
                                     backend='compiled')
    expected, expected_meta = simulate_spikes(
        frames, 129, threshold=1 / 0.6, effects=effects, seed=5,
        backend='torch')
    assert np.array_equal(compiled, expected) and meta == expected_meta
    default, _ = simulate_spikes(frames, 129, threshold=1 / 0.6,
                                 effects=effects, seed=5)  # 'auto'
    assert np.array_equal(default, compiled)


@pytest.mark.parametrize('backend, device, message', [
    ('cuda', 'cpu', "one of 'auto', 'torch', 'compiled'"),
    pytest.param('compiled', 'meta', 'runs on the CPU, not on meta',
                 marks=needs_kernel),
])
def test_a_backend_that_cannot_integrate_is_a_clear_error(backend, device,
                                                          message):
    with pytest.raises(ValueError, match=message):
        Integrator(4, 0, device, backend=backend)


def test_simulate_spikes_checks_its_backend():
    with pytest.raises(ValueError, match='backend'):
        simulate_spikes(np.zeros((1, 2, 2)), 4, backend='triton')


@pytest.mark.skipif(not torch.cuda.is_available(), reason='needs a GPU')
def test_gpu_matches_cpu_bit_for_bit():
    frames = _video(3, (32, 40))
    cpu, _ = simulate_spikes(frames, 129, threshold=1 / 0.6, seed=4)
    gpu, _ = simulate_spikes(frames, 129, threshold=1 / 0.6, seed=4,
                             device='cuda')
    assert np.array_equal(cpu, gpu)


# ------------------------------------------------------------------- scenes
def test_scene_files(tmp_path):
    scene = {'shot_noise': {'electrons': 1000}, 'jitter': None}
    as_json = tmp_path / 'scene.json'
    as_json.write_text(json.dumps(scene))
    as_yaml = tmp_path / 'scene.yaml'
    as_yaml.write_text('shot_noise: {electrons: 1000}\njitter:\n')
    direct, meta = simulate_spikes(_image(), 30, effects=scene, seed=2)
    for path in (as_json, str(as_yaml)):
        from_file, file_meta = simulate_spikes(
            _image(), 30, effects=read_scene_file(path), seed=2)
        assert np.array_equal(from_file, direct) and file_meta == meta
    empty = tmp_path / 'empty.yml'
    empty.write_text('')
    assert read_scene_file(empty) == {}


@pytest.mark.parametrize('text, suffix, message', [
    ('[1, 2]', '.json', 'must hold a mapping'),
    ('{"sparkle": {}}', '.json', 'unknown effect'),
    ('{not json', '.json', 'cannot read'),
    ('a: b', '.txt', r'\.json, \.yaml or \.yml'),
])
def test_bad_scene_files_name_the_file(tmp_path, text, suffix, message):
    path = tmp_path / ('scene' + suffix)
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        simulate_spikes(_image(), 5, effects=read_scene_file(path))
    assert str(path) in str(info.value)


def _billion_laughs():
    """A YAML scene of ~500 bytes whose aliases expand to 10**9 strings
    (the parameters of a known effect, so that an error message would
    format them)."""
    lines = ['shot_noise:', ' - &a0 [lol,lol,lol,lol,lol,lol,lol,lol,lol,lol]']
    lines += [f' - &a{i} [' + ','.join([f'*a{i - 1}'] * 10) + ']'
              for i in range(1, 9)]
    return '\n'.join(lines) + '\n'


def test_yaml_aliases_are_refused_within_bounds(tmp_path):
    """The billion laughs: refused at its first alias, fast and small,
    with an error naming the file and quoting a bounded excerpt."""
    import time
    import tracemalloc
    text = _billion_laughs()
    assert len(text) < 600
    path = tmp_path / 'laughs.yaml'
    path.write_text(text)
    tracemalloc.start()
    began = time.perf_counter()
    with pytest.raises(ValueError, match='alias') as info:
        simulate_spikes(_image(), 5, effects=read_scene_file(path))
    seconds = time.perf_counter() - began
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert seconds < 5 and peak < 100e6
    assert str(path) in str(info.value) and len(str(info.value)) < 1000
    # a single anchor without an alias is plain YAML
    path.write_text('shot_noise: &noise {electrons: 1000}\n')
    assert read_scene_file(path) == {'shot_noise': {'electrons': 1000}}


@pytest.mark.parametrize('text, suffix', [
    ('shot_noise: {electrons: "' + 'x' * 100000 + '"}', '.yaml'),
    ('{"shot_noise": {"' + 'k' * 100000 + '": 1}}', '.json'),
    ('{"' + 'sparkle' * 20000 + '": {}}', '.json'),
    ('[' * 100000 + ']' * 100000, '.json'),
    ('[' * 100000 + ']' * 100000, '.yaml'),
    ('&' + 'a' * 100000 + ' x: *' + 'a' * 100000, '.yaml'),
])
def test_scene_errors_quote_bounded_excerpts(tmp_path, text, suffix):
    path = tmp_path / ('scene' + suffix)
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        simulate_spikes(_image(), 5, effects=read_scene_file(path))
    assert str(path) in str(info.value) and len(str(info.value)) < 1000


def test_scene_files_over_the_limit_are_refused_unread(tmp_path):
    from wgse_mmseg.limits import TEXT_FILE_LIMIT_BYTES
    path = tmp_path / 'big.yaml'
    path.write_text('# ' + 'x' * TEXT_FILE_LIMIT_BYTES + '\nshot_noise: {}\n')
    with pytest.raises(ValueError, match='larger than'):
        simulate_spikes(_image(), 5, effects=read_scene_file(path))


# ------------------------------------------------------------------- errors
@pytest.mark.parametrize('kwargs, message', [
    (dict(threshold=-1.0), 'threshold'),
    (dict(threshold=0), 'threshold'),
    (dict(threshold=float('nan')), 'threshold'),
    (dict(threshold=float('inf')), 'threshold'),
    (dict(gain=-0.5), 'gain'),
    (dict(num_steps=0), 'num_steps'),
    (dict(num_steps=2.5), 'num_steps'),
    (dict(seed=-1), 'seed'),
    (dict(seed=1.5), 'seed'),
    (dict(readout_hz=0), 'readout_hz'),
])
def test_bad_settings(kwargs, message):
    args = dict(frames=_image(), num_steps=10)
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        simulate_spikes(**args)


@pytest.mark.parametrize('frames, message', [
    (np.full((1, 3, 3), 1.5), r'\[0, 1\]'),
    (np.full((1, 3, 3), -0.1), r'\[0, 1\]'),
    (np.full((1, 3, 3), np.nan), r'\[0, 1\]'),
    (np.zeros((3, 3), np.uint8), 'leading axis'),
    (np.zeros((1, 3, 3, 4), np.uint8), r'\(N, H, W, 3\)'),
    (np.zeros((0, 3, 3), np.uint8), 'non-empty'),
    (np.zeros((1, 3, 3), np.int16), 'white is not known'),
    (np.zeros((1, 3, 3), np.uint32), 'white is not known'),
])
def test_bad_frames(frames, message):
    with pytest.raises(ValueError, match=message):
        simulate_spikes(frames, 10)


@pytest.mark.parametrize('effects, message', [
    ({'sparkle': {}}, re.escape(str(sorted(EFFECTS)))),
    ({'shot_noise': {'electron': 5}}, r"unknown parameter.*\['electrons'"),
    ({'shot_noise': {'electrons': 0}}, 'shot_noise.electrons'),
    ({'shot_noise': 5}, 'must be a mapping'),
    ({'jitter': {'std': 0.7}},
     'jitter.std must be a finite number >= 0 and <= 0.5'),
    ({'hot_pixels': {'fraction': 2}}, 'hot_pixels.fraction'),
    ({'dark_current': {'rate': 'high'}}, 'dark_current.rate'),
    ({'fixed_pattern': {'sensor_seed': -3}}, 'fixed_pattern.sensor_seed'),
    ({'camera_motion': {'translation': [1]}}, 'camera_motion.translation'),
    ({'camera_motion': {'per': 'minute'}}, 'camera_motion.per'),
    ({'interpolation': {'method': 'cubic'}}, 'interpolation.method'),
    ({'camera_motion': {}, 'interpolation': {}}, 'name one'),
    (['shot_noise'], 'mapping'),
])
def test_bad_effects(effects, message):
    with pytest.raises(ValueError, match=message):
        simulate_spikes(_image(), 10, effects=effects)


@pytest.mark.parametrize('frames, effects, message', [
    (_video(3), {'camera_motion': {}}, 'still image'),
    (_image(), {'interpolation': {}}, 'N >= 2'),
    (_image(), {'camera_motion': {'zoom': -3, 'per': 'clip'}}, 'shrinks'),
])
def test_light_effects_check_the_frames(frames, effects, message):
    with pytest.raises(ValueError, match=message):
        simulate_spikes(frames, 10, effects=effects)


def test_existing_callers_keep_working():
    """wgse_mmseg.data_generation.synthetic's call: frames, num_steps,
    threshold, seed."""
    frames = np.random.default_rng(0).random((5, 6, 8))
    spikes, meta = simulate_spikes(frames, 41, threshold=1 / 0.6, seed=123)
    assert spikes.shape == (41, 6, 8) and spikes.dtype == np.uint8
    assert set(np.unique(spikes)) <= {0, 1}
    assert meta['num_frames'] == 5 and meta['effects'] == {}


def test_affine_grid_matches_torch():
    theta = torch.randn(3, 2, 3, generator=torch.Generator().manual_seed(0))
    expected = torch.nn.functional.affine_grid(theta, (3, 1, 7, 9),
                                               align_corners=True)
    assert torch.allclose(affine_grid(theta, 7, 9), expected, atol=1e-6)


_NORMAL = re.escape("in float32's normal range (0 or a magnitude in "
                    "[1.175e-38, 3.403e+38])")


@pytest.mark.parametrize('kwargs, match', [
    (dict(threshold=1e-39), 'threshold must be a finite number > 0 '
     + _NORMAL + ', got 1e-39'),
    (dict(gain=1e39), 'gain must be a finite number >= 0 ' + _NORMAL),
    (dict(gain=1e-40), 'gain must be'),
    (dict(readout_hz=1e-45), 'readout_hz must be'),
    (dict(effects={'shot_noise': {'electrons': 1e39}}),
     'shot_noise.electrons must be a finite number > 0 ' + _NORMAL),
    (dict(effects={'fixed_pattern': {'gain_std': 1e-42}}),
     'fixed_pattern.gain_std must be'),
    (dict(gain=1e30, threshold=1e-10),
     r'gain / threshold .* is 1e\+40 for gain=1e\+30 and threshold=1e-10'),
    (dict(gain=1e30, effects={'shot_noise': {'electrons': 1e38}}),
     r'charge value\(s\) of a step are NaN: the product of the gain'),
])
def test_float32_overflow_and_underflow_are_refused(kwargs, match):
    frames = np.zeros((1, 4, 4), np.uint8)
    frames[0, :2] = 255
    with pytest.raises(ValueError, match=match):
        simulate_spikes(frames, 8, **kwargs)


def test_saturating_parameters_fire_only_where_there_is_light():
    """The largest charge float32 holds saturates the lit pixels, every
    step, and leaves the black ones dark."""
    frames = np.zeros((1, 4, 4), np.uint8)
    frames[0, :2] = 255
    spikes, _ = simulate_spikes(frames, 8, gain=3e38, threshold=1.0,
                                effects={'shot_noise': {'electrons': 1.0}})
    assert spikes[:, :2].all() and not spikes[:, 2:].any()


def test_the_stream_is_bounded_as_a_product(monkeypatch):
    """Each factor within its limit, the product is checked as a whole
    before the stream is allocated; the limit is the user's to raise."""
    monkeypatch.delenv('WGSE_MMSEG_ALLOCATION_LIMIT', raising=False)
    with pytest.raises(ValueError, match=re.escape(
            'a 4096 x 4096 x 4096 stream would take 68719476736 bytes '
            '(64 GiB), more than the allocation limit of 8589934592 bytes '
            '(8 GiB): lower T, or raise the limit with '
            'WGSE_MMSEG_ALLOCATION_LIMIT=<bytes>')):
        check_allocation(4096 ** 3, 'a 4096 x 4096 x 4096 stream', 'T')
    frames = np.zeros((1, 8, 8), np.uint8)
    monkeypatch.setenv('WGSE_MMSEG_ALLOCATION_LIMIT', '2048')
    assert simulate_spikes(frames, 32)[0].shape == (32, 8, 8)
    with pytest.raises(ValueError, match=r'simulate_spikes: the 33 x 8 x 8 '
                       r'uint8 spike stream would take 2112 bytes'):
        simulate_spikes(frames, 33)
    monkeypatch.setenv('WGSE_MMSEG_ALLOCATION_LIMIT', '8 GiB')
    with pytest.raises(ValueError, match='WGSE_MMSEG_ALLOCATION_LIMIT must '
                       r"be a positive integer \(bytes\), got '8 GiB'"):
        simulate_spikes(frames, 33)
