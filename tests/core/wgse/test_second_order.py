"""Second-order gradients through WGSE's band networks (a gradient penalty:
a backward pass with ``create_graph=True``), and results that no thread
count changes.

Every backend gives them, checked against the ``'reference'`` backend in
float64 (``nn.Conv1d`` modules, differentiated by torch itself) and, for
the kernel functions, by ``gradgradcheck`` (finite differences), at one
and two torch threads; or refuses them naming the backend and ``'torch'``
(``triton``). The Triton kernel runs in triton's CPU interpreter
(``TRITON_INTERPRET=1``, set in ``conftest.py``)."""
import copy

import pytest
import torch

from wgse_mmseg.core.wgse import (WGSE, band_network_backends,
                                  compiled_band_networks,
                                  torch_band_networks)

THREADS = [1, 2]
SECOND_ORDER = [name for name in ('torch', 'compiled', 'reference')
                if band_network_backends.BACKENDS[name].unavailable() is None]


@pytest.fixture(params=THREADS, ids=lambda n: f'{n}-threads')
def threads(request):
    before = torch.get_num_threads()
    torch.set_num_threads(request.param)
    yield request.param
    torch.set_num_threads(before)


@pytest.fixture
def many_chunks(monkeypatch):
    """Chunks of a few pixels, so that two threads share every call."""
    monkeypatch.setattr(torch_band_networks, 'ROWS_PER_CHUNK', 40)
    monkeypatch.setattr(compiled_band_networks, 'ROWS_PER_CALL', 40)


def _model(backend, seed=0):
    torch.manual_seed(seed)
    model = WGSE(backend=backend)
    with torch.no_grad():  # open ReLUs: gradients not mostly zero
        for net in model.band_networks:
            for conv, _ in net.layers():
                conv.bias.uniform_(-0.2, 0.4)
    return model


def _penalised(model, spikes, input_grad):
    """The parameter gradients of ``sum(out * w) + sum(v * g ** 2)``, ``g``
    the first-order gradients (of the parameters, and of the input with
    ``input_grad``): a gradient penalty."""
    model.zero_grad()
    spikes = spikes.detach().requires_grad_(input_grad)
    out = model(spikes)
    weights = torch.linspace(-1, 1, out.numel(), dtype=out.dtype)
    loss = (out * weights.view_as(out)).sum()
    wrt = list(model.parameters()) + ([spikes] if input_grad else [])
    grads = torch.autograd.grad(loss, wrt, create_graph=True)
    penalty = sum((torch.cos(torch.arange(g.numel(), dtype=g.dtype))
                   .view_as(g) * g ** 2).sum() for g in grads)
    (loss + penalty).backward()
    return [p.grad.detach().clone() for p in model.parameters()]


def _spikes(shape=(1, 9, 5, 7), seed=1):
    generator = torch.Generator().manual_seed(seed)
    return (torch.rand(*shape, generator=generator) < 0.4).float()


@pytest.mark.parametrize('backend', SECOND_ORDER)
def test_a_gradient_penalty_matches_the_float64_reference(
        backend, threads, many_chunks):
    model = _model(backend)
    spikes = _spikes()
    input_grad = backend != 'compiled'  # it computes no input gradient
    got = _penalised(model, spikes, input_grad)
    assert model.backend_in_use == backend
    reference = copy.deepcopy(model).double()
    reference.backend = 'reference'
    want = _penalised(reference, spikes.double(), input_grad)
    largest = max(w.abs().max().item() for w in want)
    for index, (g, w) in enumerate(zip(got, want)):
        scale = max(w.abs().max().item(), 1e-2 * largest)
        err = (g.double() - w).abs().max().item() / scale
        assert err < 1e-4, f'{backend}: parameter {index} off by {err:.2e}'


def _kernel_inputs(dtype=torch.float64):
    """A band network of two bands (lengths 4 and 3) as the kernels take
    it: ``(N, C)`` coefficients and per band the layers' weights."""
    torch.manual_seed(3)
    plan = [None, 0, None]  # conv 1->4, conv 4->4 + input, conv 4->1
    shapes = [(4, 1, 3), (4, 4, 3), (1, 4, 3)]
    weights = [[(torch.randn(s, dtype=dtype, requires_grad=True),
                 torch.rand(s[0], dtype=dtype).add(0.1).requires_grad_())
                for s in shapes] for _ in range(2)]
    coeffs = torch.randn(5, 7, dtype=dtype, requires_grad=True)
    return coeffs, (4, 3), weights, plan


def test_the_torch_kernel_passes_gradgradcheck(threads, many_chunks):
    coeffs, lengths, weights, plan = _kernel_inputs()
    params = [t for band in weights for layer in band for t in layer]

    def function(coeffs, *params):
        it = iter(params)
        nested = [[(next(it), next(it)) for _ in band] for band in weights]
        return torch_band_networks.torch_band_networks(coeffs, lengths,
                                                       nested, plan)

    assert torch.autograd.gradgradcheck(function, (coeffs, *params),
                                        atol=1e-6, rtol=1e-4)


def test_triton_refuses_second_order_naming_torch():
    """The refusal runs before the kernel's backward, so the guard is
    checked on any tensor; with triton present, through WGSE too."""
    x = torch.ones(3, requires_grad=True)
    out = band_network_backends._FirstOrderOnly.apply(x * 2, 'triton')
    (grad, ) = torch.autograd.grad(out.sum(), x)  # first order: untouched
    assert torch.equal(grad, torch.full((3, ), 2.0))
    out = band_network_backends._FirstOrderOnly.apply(x * 2, 'triton')
    with pytest.raises(RuntimeError, match="backend='triton' gives no "
                       "second-order.*backend='torch'"):
        torch.autograd.grad(out.sum(), x, create_graph=True)
    if band_network_backends.BACKENDS['triton'].unavailable() is None:
        model = _model('triton')
        out = model(_spikes((1, 9, 3, 5)))
        with pytest.raises(RuntimeError, match="backend='triton'"):
            torch.autograd.grad(out.sum(), list(model.parameters()),
                                create_graph=True)


@pytest.mark.parametrize('backend', ['torch', 'compiled'])
def test_no_thread_count_changes_a_result(backend, many_chunks):
    """Outputs and gradients bit for bit at 1, 2 and 3 threads."""
    if band_network_backends.BACKENDS[backend].unavailable():
        pytest.skip(band_network_backends.BACKENDS[backend].unavailable())
    results = []
    before = torch.get_num_threads()
    try:
        for count in (1, 2, 3):
            torch.set_num_threads(count)
            model = _model(backend)
            out = model(_spikes((2, 9, 6, 7)))
            weights = torch.linspace(-1, 1, out.numel()).view_as(out)
            (out * weights).sum().backward()
            assert model.backend_in_use == backend
            results.append([out.detach()] + [p.grad for p in
                                             model.parameters()])
    finally:
        torch.set_num_threads(before)
    for other in results[1:]:
        for got, want in zip(other, results[0]):
            assert torch.equal(got, want)


@pytest.mark.parametrize('dim', [1, 2])
def test_the_torch_backends_device_path_gives_second_order(dim):
    """Off the CPU the ``'torch'`` backend runs the ``nn.Conv`` modules in
    recomputed chunks (``torch.utils.checkpoint``): run here on the CPU,
    in chunks of a few pixels, its gradient penalty equals the modules'
    with every activation kept."""
    from wgse_mmseg.core.wavelets import band_lengths
    torch.manual_seed(0)
    model = WGSE(backend='reference', dim=dim).double()
    lengths = list(band_lengths(9, model.wavelet, model.level, model.mode))
    coeffs = torch.randn(2, sum(lengths), 30, dtype=torch.float64)
    results = []
    for recompute in (True, False):
        model.zero_grad()
        out = band_network_backends._module_bands(
            model.band_networks, coeffs, lengths, (5, 6),
            recompute=recompute, chunk_bytes=20000)
        weights = torch.cos(torch.arange(out.numel(), dtype=out.dtype))
        grads = torch.autograd.grad((out * weights.view_as(out)).sum(),
                                    list(model.parameters()),
                                    create_graph=True)
        sum((g ** 2).sum() for g in grads).backward()
        results.append([p.grad.clone() for p in model.parameters()])
    for got, want in zip(*results):
        assert torch.allclose(got, want, rtol=1e-9, atol=1e-12)
