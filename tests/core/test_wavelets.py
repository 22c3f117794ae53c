"""``wgse_mmseg.core.wavelets`` against PyWavelets, the independent
reference."""
import inspect
import warnings

import numpy as np
import pytest
import pywt
import torch
from hypothesis import assume, given
from hypothesis import strategies as st

from wgse_mmseg.core.wavelets import (SUPPORTED_MODES, analysis_matrix,
                                      band_lengths, synthesis_matrix, wavedec,
                                      waverec)


pytestmark = pytest.mark.usefixtures('single_thread')

WAVELETS = ['haar', 'db1', 'db2', 'db4', 'db8', 'sym4', 'coif1', 'bior2.2',
            'rbio1.3', 'dmey']
# 'dmey' is a FIR approximation of the Meyer wavelet and is not perfectly
# reconstructing, not even in PyWavelets (round-trip error ~1e-2).
PR_WAVELETS = [w for w in WAVELETS if w != 'dmey']

wavelets = st.sampled_from(WAVELETS)
modes = st.sampled_from(SUPPORTED_MODES)
lengths = st.integers(1, 300)
levels = st.integers(1, 6)
seeds = st.integers(0, 2**32 - 1)


def _signal(seed, shape):
    return np.random.default_rng(seed).standard_normal(shape)


def _pywt_wavedec(x, wavelet, mode, level, axis=-1):
    """``pywt.wavedec`` without its level warnings; ``None`` if it refuses.

    PyWavelets refuses ``reflect`` on a 1-sample signal (which appears at
    deep levels); there is no reference to compare against there.
    """
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        try:
            return pywt.wavedec(x, wavelet, mode=mode, level=level, axis=axis)
        except ValueError as err:
            assert mode == 'reflect' and 'greater than 1' in str(err), err
            return None


@given(wavelet=wavelets, mode=modes, n=lengths, level=levels, seed=seeds)
def test_wavedec_matches_pywt(wavelet, mode, n, level, seed):
    x = _signal(seed, n)
    ref = _pywt_wavedec(x, wavelet, mode, level)
    assume(ref is not None)
    got = wavedec(torch.from_numpy(x), wavelet, mode=mode, level=level)
    assert len(got) == len(ref) == level + 1
    for g, r in zip(got, ref):
        assert g.dtype == torch.float64
        assert g.shape == r.shape
        np.testing.assert_allclose(g.numpy(), r, rtol=0, atol=1e-10)
    assert band_lengths(n, wavelet, level, mode) == tuple(len(r) for r in ref)


@given(wavelet=wavelets, mode=modes, n=lengths, level=levels, seed=seeds)
def test_waverec_matches_pywt(wavelet, mode, n, level, seed):
    x = _signal(seed, n)
    ref_coeffs = _pywt_wavedec(x, wavelet, mode, level)
    assume(ref_coeffs is not None)
    # Random coefficients (not only those of a signal) exercise the whole
    # synthesis matrix.
    rng = np.random.default_rng(seed + 1)
    coeffs = [rng.standard_normal(c.shape) for c in ref_coeffs]
    ref = pywt.waverec(coeffs, wavelet, mode=mode)
    got = waverec([torch.from_numpy(c) for c in coeffs], wavelet, mode=mode)
    assert got.shape == ref.shape
    np.testing.assert_allclose(got.numpy(), ref, rtol=0, atol=1e-10)


@given(wavelet=wavelets, mode=modes, n=st.integers(1, 60), level=levels,
       axis=st.sampled_from([0, 1, 2, -1, -2, -3]), seed=seeds)
def test_axis_matches_pywt(wavelet, mode, n, level, axis, seed):
    shape = [3, 4, 2]
    shape[axis] = n
    x = _signal(seed, shape)
    ref = _pywt_wavedec(x, wavelet, mode, level, axis=axis)
    assume(ref is not None)
    got = wavedec(torch.from_numpy(x), wavelet, mode=mode, level=level,
                  axis=axis)
    assert len(got) == len(ref)
    for g, r in zip(got, ref):
        assert g.shape == r.shape
        np.testing.assert_allclose(g.numpy(), r, rtol=0, atol=1e-10)
    ref_rec = pywt.waverec(ref, wavelet, mode=mode, axis=axis)
    got_rec = waverec(got, wavelet, mode=mode, axis=axis)
    assert got_rec.shape == ref_rec.shape
    np.testing.assert_allclose(got_rec.numpy(), ref_rec, rtol=0, atol=1e-10)


@given(wavelet=st.sampled_from(PR_WAVELETS), mode=modes, n=lengths,
       level=levels, seed=seeds)
def test_perfect_reconstruction(wavelet, mode, n, level, seed):
    x = _signal(seed, n)
    assume(_pywt_wavedec(x, wavelet, mode, level) is not None)
    xt = torch.from_numpy(x)
    rec = waverec(wavedec(xt, wavelet, mode=mode, level=level), wavelet,
                  mode=mode, length=n)
    assert rec.shape == (n, )
    np.testing.assert_allclose(rec.numpy(), x, rtol=0, atol=1e-9)


def test_perfect_reconstruction_batched_along_axis():
    x = torch.from_numpy(_signal(3, (2, 41, 3)))
    coeffs = wavedec(x, 'db8', level=5, axis=1)
    rec = waverec(coeffs, 'db8', axis=1, length=41)
    torch.testing.assert_close(rec, x, rtol=0, atol=1e-9)


@pytest.mark.parametrize('n, expected', [
    (41, (15, 15, 16, 18, 21, 28)),
    (129, (18, 18, 22, 29, 43, 72)),
])
def test_band_lengths_db8_level5_zero(n, expected):
    # Hand computation: one zero-mode step maps N samples to
    # floor((N + 16 - 1) / 2) = (N + 15) // 2 coefficients (db8: 16 taps).
    # 41 -> 28 -> 21 -> 18 -> 16 -> 15 ; 129 -> 72 -> 43 -> 29 -> 22 -> 18.
    hand, m, details = [], n, []
    for _ in range(5):
        m = (m + 15) // 2
        details.append(m)
    hand = (m, ) + tuple(details[::-1])
    assert hand == expected
    assert band_lengths(n, 'db8', 5, 'zero') == expected
    coeffs = wavedec(torch.zeros(n, dtype=torch.float64), 'db8', 'zero', 5)
    assert tuple(c.shape[0] for c in coeffs) == expected
    assert analysis_matrix(n, 'db8', 5, 'zero').shape == (sum(expected), n)
    assert synthesis_matrix(expected, 'db8', 'zero', length=n).shape == (
        n, sum(expected))


def test_default_level_is_pywt_max_level():
    x = _signal(0, 100)
    # level=None -> dwt_max_level; default mode 'symmetric', as PyWavelets
    ref = pywt.wavedec(x, 'db2')
    got = wavedec(torch.from_numpy(x), 'db2', level=None)
    assert len(got) == len(ref) == pywt.dwt_max_level(100, 'db2') + 1
    for g, r in zip(got, ref):
        np.testing.assert_allclose(g.numpy(), r, rtol=0, atol=1e-10)


def test_wavelet_object_accepted():
    x = _signal(1, 20)
    got = wavedec(torch.from_numpy(x), pywt.Wavelet('sym4'), level=2)
    ref = _pywt_wavedec(x, 'sym4', 'symmetric', 2)
    for g, r in zip(got, ref):
        np.testing.assert_allclose(g.numpy(), r, rtol=0, atol=1e-10)


def test_non_float64_inputs_use_float32():
    x = torch.randint(0, 2, (41, ), dtype=torch.uint8)
    coeffs = wavedec(x, 'db8', level=5)
    assert all(c.dtype == torch.float32 for c in coeffs)
    ref = _pywt_wavedec(x.numpy().astype(np.float64), 'db8', 'symmetric', 5)
    for g, r in zip(coeffs, ref):
        np.testing.assert_allclose(g.numpy(), r, rtol=1e-5, atol=1e-5)


def test_gradcheck_wavedec():
    x = torch.randn(2, 11, dtype=torch.float64, requires_grad=True)

    def fn(t):
        return tuple(wavedec(t, 'db2', mode='symmetric', level=2, axis=1))

    assert torch.autograd.gradcheck(fn, (x, ))


def test_gradcheck_waverec():
    lengths = band_lengths(11, 'db2', 2, 'symmetric')
    coeffs = tuple(
        torch.randn(2, n, dtype=torch.float64, requires_grad=True)
        for n in lengths)

    def fn(*cs):
        return waverec(list(cs), 'db2', mode='symmetric', axis=1, length=11)

    assert torch.autograd.gradcheck(fn, coeffs)


@pytest.mark.parametrize('name', ['notawavelet', 'morl', 'db99'])
def test_bad_wavelet_raises(name):
    x = torch.zeros(16)
    with pytest.raises(ValueError, match=name):
        wavedec(x, name, level=1)
    with pytest.raises(ValueError, match=name):
        band_lengths(16, name, 1)


def test_unsupported_mode_raises():
    x = torch.zeros(16)
    with pytest.raises(ValueError, match='smooth'):
        wavedec(x, 'db2', mode='smooth', level=1)
    coeffs = wavedec(x, 'db2', level=1)
    with pytest.raises(ValueError, match='smooth'):
        waverec(coeffs, 'db2', mode='smooth')


def test_waverec_rejects_inconsistent_coefficients():
    with pytest.raises(ValueError):
        waverec([], 'db2')
    coeffs = [torch.zeros(5), torch.zeros(9)]
    with pytest.raises(ValueError):
        waverec(coeffs, 'db2')


def test_waverec_length_out_of_range():
    coeffs = wavedec(torch.zeros(41), 'db8', level=5)
    for bad in (0, 43):
        with pytest.raises(ValueError, match=str(bad)):
            waverec(coeffs, 'db8', length=bad)
    # pywt.waverec returns 42 samples here; length=42 is still allowed.
    assert waverec(coeffs, 'db8', length=42).shape == (42, )


@pytest.mark.parametrize('ours, theirs', [(wavedec, pywt.wavedec),
                                          (waverec, pywt.waverec)])
def test_public_functions_follow_pywavelets_signature(ours, theirs):
    """Same parameter names, order and defaults as PyWavelets (ours adds
    ``length`` to waverec), so code moves between the two unchanged."""
    mine = inspect.signature(ours).parameters
    pywt_params = inspect.signature(theirs).parameters
    assert list(mine)[:len(pywt_params)] == list(pywt_params)
    for name, param in pywt_params.items():
        assert mine[name].default == param.default, name
    x = torch.linspace(0, 1, 20, dtype=torch.float64)
    np.testing.assert_allclose(
        [c.numpy() for c in wavedec(x, 'db2')][0],
        pywt.wavedec(x.numpy(), 'db2')[0])


@given(wavelet=wavelets, n=st.integers(1, 64), level=st.integers(0, 24))
def test_a_level_too_high_warns_as_pywavelets_does(wavelet, n, level):
    """A level above ``pywt.dwt_max_level`` is transformed (no cap) and
    warns exactly where PyWavelets' own ``wavedec`` warns."""
    x = np.linspace(0, 1, n)
    with warnings.catch_warnings(record=True) as theirs:
        warnings.simplefilter('always')
        expected = pywt.wavedec(x, wavelet, mode='zero', level=level)
    with warnings.catch_warnings(record=True) as ours:
        warnings.simplefilter('always')
        got = wavedec(torch.from_numpy(x), wavelet, mode='zero', level=level)
    assert [str(w.message) for w in ours] == [str(w.message) for w in theirs]
    assert [c.shape[0] for c in got] == [len(c) for c in expected]


def test_an_empty_signal_is_named():
    with pytest.raises(ValueError, match=r'wavedec: data\.shape\[axis\] '
                       r'must be an integer >= 1, got 0'):
        wavedec(torch.zeros(3, 0), 'haar', level=1)
