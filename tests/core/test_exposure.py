"""Exposure normalisation against hand-computed gains."""
import argparse

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from wgse_mmseg.command_line import EXPOSURE
from wgse_mmseg.core.exposure import (UNDER_EXPOSED_BELOW, apply_exposure,
                                      exposure_gain)


def test_a_dark_image_gets_its_bright_end_to_white_ignoring_hot_pixels():
    image = np.full((20, 20), 0.05)
    image[0, 0] = 1.0  # one hot pixel in 400: above the 99.5th percentile
    assert exposure_gain(image) == pytest.approx(20.0)
    exposed, gain, reason = apply_exposure(image)
    assert gain == pytest.approx(20.0)
    assert 'under-exposed' in reason and '0.05' in reason
    assert exposed.dtype == np.float32
    np.testing.assert_allclose(exposed, np.minimum(image * 20, 1), rtol=1e-6)


@pytest.mark.parametrize('bright', [0.26, 0.5, 0.775, 1.0, 4.0])
def test_an_image_of_normal_brightness_passes_untouched(bright):
    """A calibrated image is never rescaled by 'auto': neither brightened
    (which clipped the REDS stream's highlights) nor darkened."""
    image = np.linspace(0, bright, 400).reshape(20, 20)
    exposed, gain, reason = apply_exposure(image)
    assert gain == 1.0 and 'left as it is' in reason
    np.testing.assert_array_equal(exposed, np.clip(image, 0, 1).astype(
        np.float32))
    assert exposure_gain(np.full((4, 4), UNDER_EXPOSED_BELOW)) == 1.0


def test_black_limits_and_fixed_gains():
    assert exposure_gain(np.zeros((4, 4))) == 1.0
    sparse = np.zeros((40, 40))
    sparse[0, 0] = 0.5  # black at the percentile, not everywhere
    assert exposure_gain(sparse) == 64.0
    assert exposure_gain(np.full((4, 4), 1e-6)) == 64.0
    assert exposure_gain(np.full((4, 4), 0.2), max_gain=2) == 2.0
    image = np.full((2, 2), 0.1)
    assert apply_exposure(image, 'none').gain == 1.0
    np.testing.assert_allclose(apply_exposure(image, 2.0).image, 0.2,
                               rtol=1e-6)


@pytest.mark.parametrize('bad', ['dim', -1.0, 0.0, float('nan'),
                                 float('inf')])
def test_bad_exposures_are_refused(bad):
    with pytest.raises(ValueError, match='exposure'):
        apply_exposure(np.ones((2, 2)), bad)


def test_bad_images_are_refused():
    with pytest.raises(ValueError, match='non-empty, finite'):
        exposure_gain(np.array([[0.1, np.nan]]))
    with pytest.raises(ValueError, match='non-empty, finite'):
        exposure_gain(np.zeros((0, 3)))
    with pytest.raises(ValueError, match='under_exposed_below'):
        exposure_gain(np.ones((2, 2)), under_exposed_below=0)


def test_exposure_on_a_command_line():
    assert EXPOSURE('auto') == 'auto'
    assert EXPOSURE('none') == 'none'
    assert EXPOSURE('2.5') == 2.5
    for text in ('0', '-3', 'nan', 'inf', 'bright', ''):
        with pytest.raises(argparse.ArgumentTypeError,
                           match="must be one of \\['auto', 'none'\\], or a "
                           'finite number > 0'):
            EXPOSURE(text)


@given(arrays(np.float64, (6, 7), elements=st.floats(0, 10)))
def test_auto_output_is_in_range_and_monotone(image):
    exposed, gain, _ = apply_exposure(image)
    assert 1 <= gain <= 64
    if np.percentile(image, 99.5) >= UNDER_EXPOSED_BELOW:
        assert gain == 1
    assert exposed.min() >= 0 and exposed.max() <= 1
    order = np.argsort(image, axis=None, kind='stable')
    assert np.all(np.diff(exposed.ravel()[order]) >= 0)
