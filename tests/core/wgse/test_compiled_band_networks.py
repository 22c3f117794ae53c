"""The compiled band network kernel against the band networks run as
``nn.Conv1d`` modules in float64, its fallbacks and its determinism."""
import copy
import shutil

import pytest
import torch
import torch.nn.functional as F
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from wgse_mmseg.core.wgse import WGSE, compiled_band_networks
from wgse_mmseg.core.wgse.band_network import BandNetwork

pytestmark = pytest.mark.usefixtures('single_thread')
needs_kernel = pytest.mark.skipif(
    compiled_band_networks.unavailable() is not None,
    reason=str(compiled_band_networks.unavailable()))


def _networks(num_bands, num_blocks, seed=0, hidden=32, kernel=3):
    torch.manual_seed(seed)
    networks = [BandNetwork(1, kernel, hidden, num_blocks)
                for _ in range(num_bands)]
    # Larger biases than the default init keep many ReLUs open.
    with torch.no_grad():
        for net in networks:
            for conv, _ in net.layers():
                conv.bias.uniform_(-0.3, 0.5)
    residuals = [residual for _, residual in networks[0].layers()]
    weights = [[(conv.weight, conv.bias) for conv, _ in net.layers()]
               for net in networks]
    return networks, weights, residuals


def _reference(networks, coeffs, lengths, grad_out):
    """Output and parameter gradients of the modules in float64."""
    outs, grads = [], []
    for net, band, grad in zip(networks, coeffs.split(lengths, 1),
                               grad_out.split(lengths, 1)):
        double = copy.deepcopy(net).double()
        out = double(band.double().unsqueeze(1)).squeeze(1)
        grads += torch.autograd.grad((out * grad.double()).sum(),
                                     list(double.parameters()))
        outs.append(out.detach())
    return torch.cat(outs, 1), grads


#: Pre-activations closer to zero than this may land on the other side of
#: a ReLU in float32 (measured: a float64 pre-activation of 4e-8 did), where
#: the gradient jumps; pixels with one are not compared. (A pixel's band
#: networks see only its own coefficients.)
KINK_MARGIN = 1e-5


def _clear_of_kinks(networks, coeffs, lengths):
    """``(pixels,)`` bool: whether every ReLU input of the pixel, over all
    bands, is at least :data:`KINK_MARGIN` from zero, in float64."""
    clear = torch.ones(coeffs.shape[0], dtype=torch.bool)
    with torch.no_grad():
        for net, band in zip(networks, coeffs.split(lengths, 1)):
            acts = [band.double().unsqueeze(1)]
            for conv, residual in net.layers():
                pre = F.conv1d(acts[-1], conv.weight.double(),
                               conv.bias.double(), padding=conv.padding)
                if residual is not None:
                    pre = pre + acts[residual]
                clear &= pre.abs().amin(dim=(1, 2)) > KINK_MARGIN
                acts.append(F.relu(pre))
    return clear


def _compiled(weights, residuals, coeffs, lengths, grad_out):
    out = compiled_band_networks.compiled_band_networks(
        coeffs, lengths, weights, residuals)
    params = [t for band in weights for layer in band for t in layer]
    return out.detach(), torch.autograd.grad((out * grad_out).sum(), params)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**16), pixels=st.integers(1, 60),
       lengths=st.lists(st.integers(1, 80), min_size=1, max_size=4),
       num_blocks=st.integers(1, 2), rows_per_call=st.integers(1, 400))
@needs_kernel
def test_equals_conv_modules(seed, pixels, lengths, num_blocks,
                             rows_per_call):
    """Outputs and every parameter gradient, float32 against float64
    modules, for chunks from one pixel to all and band lengths from one
    coefficient to more than a cache-sized group holds (away from ReLU
    kinks, where float32 and float64 may take different sides)."""
    networks, weights, residuals = _networks(len(lengths), num_blocks, seed)
    generator = torch.Generator().manual_seed(seed)
    coeffs = torch.randn(pixels, sum(lengths), generator=generator)
    grad_out = torch.randn(pixels, sum(lengths), generator=generator)
    # The larger examples almost always have a pixel near a kink (filtering
    # whole examples left mostly small ones, and failed Hypothesis's health
    # check at random): such pixels take no part in the comparison and add
    # nothing to the gradients.
    clear = _clear_of_kinks(networks, coeffs, lengths)
    assume(clear.any())
    grad_out[~clear] = 0
    compiled_band_networks.ROWS_PER_CALL = rows_per_call
    try:
        out, grads = _compiled(weights, residuals, coeffs, lengths,
                               grad_out)
    finally:
        compiled_band_networks.ROWS_PER_CALL = 16384
    expected, expected_grads = _reference(networks, coeffs, lengths,
                                          grad_out)
    torch.testing.assert_close(out[clear].double(), expected[clear],
                               rtol=1e-5, atol=1e-5)
    for grad, want in zip(grads, expected_grads):
        scale = want.abs().max().item() + 1e-3
        # float32 sums over up to 1,024 rows per group, in another order
        torch.testing.assert_close(grad.double() / scale, want / scale,
                                   rtol=0, atol=1e-4)


@needs_kernel
def test_long_bands_span_several_groups():
    """1,200 coefficients per pixel: more rows than one cache-sized group
    (1,024), so each pixel is a group of its own."""
    networks, weights, residuals = _networks(1, 1, seed=3)
    coeffs = torch.randn(3, 1200)
    grad_out = torch.randn(3, 1200)
    out, grads = _compiled(weights, residuals, coeffs, [1200], grad_out)
    expected, expected_grads = _reference(networks, coeffs, [1200], grad_out)
    torch.testing.assert_close(out.double(), expected, rtol=1e-5, atol=1e-5)
    for grad, want in zip(grads, expected_grads):
        torch.testing.assert_close(grad.double(), want, rtol=1e-4,
                                   atol=1e-4)


@needs_kernel
@pytest.mark.parametrize('num_blocks', [1, 2], ids=['paper', 'long'])
def test_wgse_uses_it_and_agrees_with_the_torch_kernel(num_blocks,
                                                       monkeypatch):
    """'auto' on the CPU runs the compiled kernel; the 'torch' backend
    computes the same."""
    torch.manual_seed(0)
    model = WGSE(num_blocks=num_blocks)
    x = (torch.rand(2, 41, 9, 11) < 0.4).float()
    calls = []
    original = compiled_band_networks.compiled_band_networks
    monkeypatch.setattr(compiled_band_networks, 'compiled_band_networks',
                        lambda *a: calls.append(1) or original(*a))
    results = []
    for backend in ('auto', 'torch'):
        model.backend = backend
        model.zero_grad()
        y = model(x)
        y.square().mean().backward()
        results.append([y.detach()] + [p.grad.clone()
                                       for p in model.parameters()])
        assert model.backend_in_use == ('compiled' if backend == 'auto'
                                        else 'torch')
    assert calls == [1]
    for compiled, torch_kernel in zip(*results):
        torch.testing.assert_close(compiled, torch_kernel, rtol=1e-4,
                                   atol=1e-6)


@pytest.mark.parametrize('case', ['float64', 'input-grad', 'hidden-8',
                                  'kernel-5'])
@needs_kernel
def test_falls_back_where_it_does_not_apply(case):
    """Other dtypes, widths and kernels, and a gradient for the input:
    :func:`unsupported` says why, and the kernel refuses to run."""
    _, weights, residuals = _networks(
        2, 1, hidden=8 if case == 'hidden-8' else 32,
        kernel=5 if case == 'kernel-5' else 3)
    coeffs = torch.randn(4, 10, dtype=torch.float64 if case == 'float64'
                         else torch.float32,
                         requires_grad=case == 'input-grad')
    reason = compiled_band_networks.unsupported(coeffs, weights, residuals)
    assert reason
    with pytest.raises(ValueError, match='does not apply'):
        compiled_band_networks.compiled_band_networks(coeffs, [4, 6],
                                                      weights, residuals)
    plain = torch.randn(4, 10)
    if case in ('hidden-8', 'kernel-5'):
        assert compiled_band_networks.unsupported(plain, weights, residuals)
    else:
        assert compiled_band_networks.unsupported(plain, weights,
                                                  residuals) is None


@needs_kernel
def test_no_pixels():
    _, weights, residuals = _networks(2, 1)
    out, grads = _compiled(weights, residuals, torch.zeros(0, 10), [4, 6],
                           torch.zeros(0, 10))
    assert out.shape == (0, 10)
    assert all(torch.equal(g, torch.zeros_like(g)) for g in grads)


@needs_kernel
def test_threads_give_the_same_bits():
    """Chunks side by side on two threads: every run gives the same bits,
    and outputs equal the one-thread run's."""
    compiled_band_networks.ROWS_PER_CALL = 300
    _, weights, residuals = _networks(3, 2)
    coeffs, grad_out = torch.randn(2, 200, 90)

    def run(threads):
        torch.set_num_threads(threads)
        return _compiled(weights, residuals, coeffs, [30, 40, 20], grad_out)

    try:
        first, second, single = run(2), run(2), run(1)
    finally:
        torch.set_num_threads(1)
        compiled_band_networks.ROWS_PER_CALL = 16384
    assert torch.equal(first[0], second[0]) and torch.equal(first[0],
                                                            single[0])
    for a, b, c in zip(first[1], second[1], single[1]):
        assert torch.equal(a, b)
        torch.testing.assert_close(a, c, rtol=1e-6, atol=1e-7)


@pytest.mark.skipif(shutil.which('cc') is None, reason='no C compiler')
def test_built_where_a_compiler_is():
    """The extension is optional in ``setup.py``: a failed build must not
    go unnoticed where it could have succeeded."""
    assert compiled_band_networks.unavailable() != \
        compiled_band_networks.NOT_BUILT
