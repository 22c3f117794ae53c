"""WGSE's band-network backends: choosing one, clear errors, and every
backend against the band networks run as float64 ``nn.Conv1d`` modules
(outputs, input gradients, every parameter gradient). The Triton kernel
runs in triton's CPU interpreter (``TRITON_INTERPRET=1``, set in
``conftest.py``)."""
import contextlib
import copy
import types
import warnings

import pytest
import torch

from mmseg.registry import MODELS

import wgse_mmseg
from wgse_mmseg.core.wgse import WGSE, band_network_backends, \
    compiled_band_networks, triton_band_networks, triton_launch_choices

wgse_mmseg.register_all_modules()  # MODELS.build(dict(type='WGSE'))
pytestmark = pytest.mark.usefixtures('single_thread')

needs_compiled = pytest.mark.skipif(
    compiled_band_networks.unavailable() is not None,
    reason=str(compiled_band_networks.unavailable()))


def _model(seed=0, **kwargs):
    torch.manual_seed(seed)
    model = WGSE(**kwargs)
    # Larger biases than the default init keep many ReLUs open, so the
    # gradients are not mostly zero.
    with torch.no_grad():
        for net in model.band_networks:
            for conv, _ in net.layers():
                conv.bias.uniform_(-0.2, 0.4)
    return model


def _run(model, spikes, input_grad):
    """Output, input gradient (or None) and parameter gradients of
    ``sum(out * w)`` for a fixed ``w``."""
    model.zero_grad()
    spikes = spikes.detach().requires_grad_(input_grad)
    out = model(spikes)
    weights = torch.linspace(-1, 1, out.numel(), dtype=out.dtype)
    (out * weights.view_as(out)).sum().backward()
    return [out.detach(), spikes.grad] + [p.grad for p in model.parameters()]


def _reference(model, spikes, input_grad):
    """The same model in float64 on the ``'reference'`` backend: the band
    networks as ``nn.Conv1d`` modules, one signal per pixel
    (``torch.jit``-free, chunk-free)."""
    double = copy.deepcopy(model).double()
    double.backend = 'reference'
    result = _run(double, spikes.double(), input_grad)
    assert double.backend_in_use == 'reference'
    return result


def _assert_close(got, want, tol, what):
    """Each tensor within ``tol`` of the largest magnitude in it, or of a
    hundredth of the largest in any (a gradient that cancels to ~0 has no
    meaningful relative error)."""
    largest = max(w.abs().max().item() for w in want
                  if w is not None and w.numel())
    for index, (g, w) in enumerate(zip(got, want)):
        if w is None:
            assert g is None, (what, index)
            continue
        scale = max(w.abs().max().item(), 1e-2 * largest)
        err = (g.double() - w).abs().max().item() / scale
        assert err <= tol, f'{what}: tensor {index} off by {err:.2e}'


def _spikes(batch, steps, height, width, seed=1):
    generator = torch.Generator().manual_seed(seed)
    return (torch.rand(batch, steps, height, width, generator=generator)
            < 0.4).float()


# ------------------------------------------------------------- choosing
def test_unknown_backend_lists_the_choices():
    with pytest.raises(ValueError) as error:
        WGSE(backend='cuda')
    for name in ('auto', 'torch', 'compiled', 'triton', 'reference', "'cuda'"):
        assert name in str(error.value)


@pytest.mark.parametrize('backend, kwargs, reason', [
    ('compiled', dict(dim=2), 'dim=1'),
    ('triton', dict(dim=3), 'dim=1'),
    ('triton', dict(num_blocks=2), 'num_blocks=1'),
    ('triton', dict(hidden_channels=8), 'hidden_channels'),
    ('triton', dict(hidden_channels=64), 'hidden_channels'),
])
def test_a_backend_that_cannot_run_the_variant_fails_when_built(
        backend, kwargs, reason):
    if band_network_backends.BACKENDS[backend].unavailable():
        pytest.skip(f'{backend} unavailable here')
    with pytest.raises(ValueError, match=reason):
        MODELS.build(dict(type='WGSE', backend=backend, **kwargs))


def test_an_unavailable_backend_says_why(monkeypatch):
    monkeypatch.setattr(triton_band_networks, 'unavailable',
                        lambda: 'triton does not import (test)')
    with pytest.raises(ValueError, match=r'does not import \(test\)'):
        WGSE(backend='triton')
    assert WGSE(backend='auto').backend == 'auto'


@pytest.mark.needs_triton
def test_triton_on_a_cpu_tensor_outside_the_interpreter(monkeypatch):
    model = WGSE(backend='triton')
    monkeypatch.setenv('TRITON_INTERPRET', '0')
    with pytest.raises(ValueError, match='cuda tensors'):
        model(torch.zeros(1, 9, 2, 2))


@needs_compiled
def test_compiled_refuses_what_it_cannot_compute():
    """A float64 or float16 module, or a gradient for the input: a named
    backend does not fall back, naming the dtype; ``'auto'`` does, and says
    which ran."""
    model = WGSE(backend='compiled')
    for dtype in (torch.float64, torch.float16):
        with pytest.raises(ValueError, match=f'cannot run on {dtype} '
                           f'coefficients on cpu: it runs float32'):
            copy.deepcopy(model).to(dtype)(torch.zeros(1, 9, 2, 2))
    with pytest.raises(ValueError, match='no gradient for its input'):
        model(torch.zeros(1, 9, 2, 2, requires_grad=True))
    model.backend = 'auto'
    model(torch.zeros(1, 9, 2, 2, requires_grad=True))
    assert model.backend_in_use == 'torch'
    model(torch.zeros(1, 9, 2, 2))
    assert model.backend_in_use == 'compiled'


@pytest.mark.parametrize('kwargs', [dict(dim=2), dict(kernel_size=5),
                                    dict(hidden_channels=8)])
def test_auto_on_cpu_runs_torch_where_the_kernels_do_not_apply(kwargs):
    model = WGSE(**kwargs)
    assert model.backend_in_use is None
    model(torch.zeros(1, 9, 2, 2))
    assert model.backend_in_use == 'torch'


# ------------------------------------------------------- agreement
AVAILABLE = [name for name, backend in band_network_backends.BACKENDS.items()
             if backend.unavailable() is None]
# (B, T, H, W): odd T; T shorter than db8's 16-tap filter; pixel counts
# that are not a multiple of the Triton tiles (16 pixels in the first
# launch entries) and span several of them.
SHAPES = [(1, 41, 5, 7), (2, 3, 3, 5), (1, 9, 9, 11)]
#: The Triton kernel in its interpreter, which runs its programs one after
#: another: bands up to 28 over two tiles, the second partial (21 pixels),
#: and bands of 9-14, as T=3 gives them, in one partial tile; 1x9x9x11
#: adds nothing to its paths, and the launch-entry test below spans two of
#: each entry's tiles.
TRITON_SHAPES = [(1, 41, 3, 7), (1, 3, 3, 5)]
BACKEND_SHAPES = [(backend, shape) for backend in AVAILABLE for shape in
                  (TRITON_SHAPES if backend == 'triton' else SHAPES)]


@pytest.mark.parametrize('backend, shape', BACKEND_SHAPES,
                         ids=lambda v: 'x'.join(map(str, v))
                         if isinstance(v, tuple) else v)
def test_every_backend_matches_float64_modules(backend, shape):
    model = _model(backend=backend)
    spikes = _spikes(*shape)
    input_grad = backend != 'compiled'  # it computes no input gradient
    got = _run(model, spikes, input_grad)
    assert model.backend_in_use == backend
    _assert_close(got, _reference(model, spikes, input_grad),
                  triton_band_networks.TOLERANCES['ieee'], backend)


@pytest.mark.parametrize('backend', AVAILABLE)
def test_every_backend_without_pixels(backend):
    model = _model(backend=backend)
    out = model(torch.zeros(0, 9, 4, 4))
    out.sum().backward()
    assert out.shape == (0, 9, 4, 4)
    for p in model.parameters():
        assert torch.equal(p.grad, torch.zeros_like(p))


@pytest.mark.needs_triton
@pytest.mark.parametrize('hidden', triton_band_networks.HIDDEN_CHANNELS)
def test_triton_widths_and_no_wavelet(hidden):
    """Every width the kernel takes, and the TRCNN-only variant (one band
    of ``T`` coefficients)."""
    for kwargs in (dict(hidden_channels=hidden),
                   dict(hidden_channels=hidden, wavelet=None)):
        model = _model(backend='triton', **kwargs)
        spikes = _spikes(1, 13, 3, 3, seed=hidden)
        _assert_close(_run(model, spikes, True),
                      _reference(model, spikes, True), 1e-4, str(kwargs))


@pytest.mark.needs_triton
@pytest.mark.parametrize('hidden', triton_band_networks.HIDDEN_CHANNELS)
@pytest.mark.parametrize('together', [True, False])
def test_both_forward_step_forms_compute_the_same(monkeypatch, hidden,
                                                  together):
    """The forward's conv2 as one product of taps 0 and 1 (sm_90's form
    on tensor cores) and as three products (every other target's, and
    full float32's), over a full tile of pixels and a partial one, match
    float64."""
    monkeypatch.setattr(triton_launch_choices, 'taps_as_one_product',
                        lambda *args: together)
    monkeypatch.setattr(torch.backends.cudnn, 'allow_tf32', False)
    model = _model(backend='triton', hidden_channels=hidden)
    spikes = _spikes(1, 13, 1, 128 + 7, seed=hidden)
    _assert_close(_run(model, spikes, False), _reference(model, spikes, False),
                  triton_band_networks.TOLERANCES['ieee'],
                  f'taps together {together}')


@pytest.mark.needs_triton
@pytest.mark.parametrize('steps', [1, 2])
def test_triton_on_bands_shorter_than_its_kernel(steps):
    """A band of one or two coefficients (the TRCNN-only variant at T = 1
    and 2; db8's bands are 8 or longer), where every window of the
    kernel reaches past the band's ends, with and without the input
    gradient."""
    model = _model(backend='triton', wavelet=None)
    spikes = _spikes(1, steps, 3, 7, seed=steps)  # 21 pixels: 16 + 5
    for input_grad in (True, False):
        _assert_close(_run(model, spikes, input_grad),
                      _reference(model, spikes, input_grad),
                      triton_band_networks.TOLERANCES['ieee'],
                      f'T={steps}, input_grad={input_grad}')


@pytest.mark.needs_triton
@pytest.mark.parametrize('entry', triton_launch_choices.backward_configs(),
                         ids=lambda c: c.name)
def test_every_triton_backward_entry_computes_the_same(monkeypatch, entry):
    """Each backward entry a GPU may run (every target's, with and without
    the input gradient), behind the forward's entry, over two samples of
    two tiles and a partial third each, so that its programs (two a band
    here) run several tiles, matches float64 (full float32 products; the
    fp16/bf16 paths run in the autocast test below)."""
    monkeypatch.setattr(triton_launch_choices, 'backward_configs',
                        lambda *args: (entry, ))
    monkeypatch.setattr(torch.backends.cudnn, 'allow_tf32', False)
    model = _model(backend='triton')
    spikes = _spikes(2, 9, 1, 2 * entry.block + 1, seed=entry.block)
    for input_grad in (True, False):
        _assert_close(_run(model, spikes, input_grad),
                      _reference(model, spikes, input_grad),
                      triton_band_networks.TOLERANCES['ieee'],
                      f'{entry}, input gradient {input_grad}')


def test_a_kernel_is_launched_on_its_tensors_device(monkeypatch):
    """Triton launches on torch's current device: a CUDA tensor's own
    device is made current for the launch (a model on cuda:1 while cuda:0
    is current), a CPU tensor's (the interpreter) changes nothing."""
    made_current = []

    def device(where):
        made_current.append(where)
        return contextlib.nullcontext()

    monkeypatch.setattr(torch.cuda, 'device', device)
    on_cuda_1 = types.SimpleNamespace(is_cuda=True,
                                      device=torch.device('cuda', 1))
    with triton_band_networks.on_device_of(on_cuda_1):
        pass
    with triton_band_networks.on_device_of(torch.zeros(1)):
        pass
    assert made_current == [torch.device('cuda', 1)]


@pytest.mark.needs_triton
@pytest.mark.parametrize('input_grad', [False, True])
def test_both_kernels_launch_within_their_devices_context(monkeypatch,
                                                          input_grad):
    """Each launch, forward and backward, is made inside
    :func:`on_device_of` of the coefficients it reads."""
    inside = []
    launches = []
    on_device_of = triton_band_networks.on_device_of

    @contextlib.contextmanager
    def noting(tensor):
        inside.append(tensor.shape)
        with on_device_of(tensor):
            yield
        inside.pop()

    def watch(kernel):
        class Launcher:
            def __getitem__(self, grid):
                def launch(*args, **kwargs):
                    launches.append((kernel, list(inside)))
                    return getattr(kernels, kernel)[grid](*args, **kwargs)
                return launch
        return Launcher()

    kernels = triton_band_networks.kernels
    watched = types.SimpleNamespace(band_forward=watch('band_forward'),
                                    band_backward=watch('band_backward'))
    monkeypatch.setattr(triton_band_networks, 'on_device_of', noting)
    monkeypatch.setattr(triton_band_networks, 'kernels', watched)
    # the watchers are no triton kernels for the ops' tracing wrapper
    monkeypatch.setattr(torch.library, 'wrap_triton', lambda kernel: kernel)
    model = _model(backend='triton')
    _run(model, _spikes(1, 9, 1, 3), input_grad)
    assert [kernel for kernel, _ in launches] == ['band_forward',
                                                  'band_backward']
    for _, contexts in launches:  # within one, of the (B, C, P) coeffs
        assert len(contexts) == 1
        batch, _, pixels = contexts[0]
        assert (batch, pixels) == (1, 3)


@pytest.mark.needs_triton
def test_the_work_division_shares_programs_by_band_length():
    """About the slots, in proportion to a band's steps, one at least and
    no more than half its tiles; each band's programs start at tiles 0 ..
    n-1 and step by n, so together they run every tile once."""
    division = triton_launch_choices.work_division([18, 18, 72], 100, 40)
    counts = {band: step for band, first, step in division if first == 0}
    assert counts == {0: 7, 1: 7, 2: 26}
    for band, count in counts.items():
        tiles = sorted(t for b, first, step in division if b == band
                       for t in range(first, 100, step))
        assert tiles == list(range(100))
    assert triton_launch_choices.work_division([5, 500], 7, 8) == [
        (0, 0, 1), (1, 0, 3), (1, 1, 3), (1, 2, 3)]
    assert triton_launch_choices.work_division([5, 500], 3, 8) == [
        (0, 0, 1), (1, 0, 1)]


@pytest.mark.needs_triton
@pytest.mark.parametrize('programs', [2 * 108, 2 * 132, 2 * 148])
def test_the_first_use_check_runs_every_program_over_several_tiles(programs):
    """On a GPU (two programs on each of an A100's, H100's or B200's SMs)
    the check's problem still gives every backward program two tiles or
    more: the sums carried from tile to tile run on the device before
    training relies on them."""
    pixels = band_network_backends.TritonBackend.check_pixels
    for lengths in ([18, 18, 22, 29, 43, 72], [129]):
        for config in triton_launch_choices.backward_configs():
            tiles = -(-pixels // config.block)
            for band, first, step in triton_launch_choices.work_division(
                    lengths, tiles, programs):
                assert len(range(first, tiles, step)) >= 2


@pytest.mark.needs_triton
@pytest.mark.parametrize('allow_tf32, precision', [(True, 'tf32'),
                                                   (False, 'ieee')])
def test_full_float32_trains_on_the_sixteen_pixel_backward(
        monkeypatch, allow_tf32, precision):
    """A training call (no input gradient) launches the backward's 32-pixel
    entry at TF32 and the 16-pixel one in full float32, whose products on
    the FMA units spill at 32 pixels (docs/wgse_speed.md); an unknown
    precision is refused by name."""
    launched = []
    launch = triton_band_networks.launch_backward

    def noting(config, *args):
        launched.append(config)
        return launch(config, *args)

    monkeypatch.setattr(triton_band_networks, 'launch_backward', noting)
    monkeypatch.setattr(torch.backends.cudnn, 'allow_tf32', allow_tf32)
    model = _model(backend='triton', wavelet='haar', level=1)
    _run(model, _spikes(1, 4, 1, 3), False)
    assert launched == [triton_launch_choices.LaunchConfig(
        *(32, 4) if allow_tf32 else (16, 4, 255))]
    assert launched == list(triton_launch_choices.backward_configs(
        False, precision))
    with pytest.raises(ValueError, match="precision must be one of.*'fp32'"):
        triton_launch_choices.backward_configs(False, 'fp32')


@pytest.mark.needs_triton
def test_triton_rejects_a_launch_config_not_in_its_lists():
    coeffs = torch.zeros(1, 5, 4)
    model = _model(backend='triton')
    weights = [[(conv.weight, conv.bias) for conv, _ in net.layers()]
               for net in model.band_networks[:1]]
    with pytest.raises(ValueError, match='forward_config must be one of'):
        triton_band_networks.triton_band_networks(
            coeffs, [5], weights, forward_config=(
                triton_launch_choices.LaunchConfig(128, 2)))


@pytest.mark.needs_triton
@pytest.mark.parametrize('dtype', [torch.float16, torch.bfloat16],
                         ids=['fp16', 'bf16'])
def test_triton_under_autocast_within_its_stated_tolerance(dtype):
    """Under autocast the hidden products take fp16/bf16 operands; output
    and gradients stay within :data:`TOLERANCES` of float64."""
    model = _model(backend='triton')
    # one partial tile; bands of 15: the precision changes the products'
    # operands, not the tiling (two tiles: the tests above)
    spikes = _spikes(1, 16, 3, 5)
    precision = {torch.float16: 'fp16', torch.bfloat16: 'bf16'}[dtype]
    with torch.autocast('cpu', dtype=dtype):
        assert triton_launch_choices.dot_precision('cpu') == precision
        got = _run(model, spikes, True)
    assert got[0].dtype == torch.float32
    _assert_close(got, _reference(model, spikes, True),
                  triton_band_networks.TOLERANCES[precision], precision)


def test_dot_precision_follows_torch_flags(monkeypatch):
    monkeypatch.setattr(torch.backends.cudnn, 'allow_tf32', True)
    assert triton_launch_choices.dot_precision('cpu') == 'tf32'
    monkeypatch.setattr(torch.backends.cudnn, 'allow_tf32', False)
    assert triton_launch_choices.dot_precision('cpu') == 'ieee'


@pytest.mark.needs_triton
@pytest.mark.parametrize('call, match', [
    (lambda w: triton_band_networks.triton_band_networks(
        torch.zeros(2, 5), [2, 2], w), 'do not fit'),
    (lambda w: triton_band_networks.triton_band_networks(
        torch.zeros(2, 4, dtype=torch.float64), [2, 2], w), 'float32'),
    (lambda w: triton_band_networks.triton_band_networks(
        torch.zeros(2, 4), [2, 2], w, precision='fp8'), 'precision'),
], ids=['lengths', 'dtype', 'precision'])
def test_triton_function_rejects_bad_arguments(call, match):
    model = _model(level=1, wavelet='haar')
    weights, _ = band_network_backends._weights(model.band_networks)
    with pytest.raises(ValueError, match=match):
        call(weights)


# ---------------------------------------- the torch backend off the CPU

def _device_path(budget):
    """The ``'torch'`` backend's path for CUDA tensors (``nn.Conv1d``
    chunks of ``budget`` bytes, each recomputed), forced on CPU tensors."""
    class DevicePath(band_network_backends.TorchBackend):
        def run(self, networks, coeffs, lengths, spatial,
                output_grad_is_scratch=False):
            return band_network_backends._module_bands(
                networks, coeffs, lengths, spatial, recompute=True,
                chunk_bytes=budget)
    return DevicePath()


@pytest.mark.parametrize('kwargs', [dict(), dict(num_blocks=2,
                                                 hidden_channels=5)],
                         ids=['paper', 'long'])
@pytest.mark.parametrize('budget', [1, 40_000, 1 << 29],
                         ids=['a-pixel-a-chunk', 'several', 'one-chunk'])
def test_torch_device_path_matches_float64_modules(monkeypatch, kwargs,
                                                   budget):
    """Every chunking (one pixel, several chunks with a partial last one,
    one chunk) in float64 against the modules run whole."""
    monkeypatch.setitem(band_network_backends.BACKENDS, 'torch',
                        _device_path(budget))
    model = _model(backend='torch', **kwargs).double()
    spikes = _spikes(1, 21, 5, 7).double()
    got = _run(model, spikes, True)
    _assert_close(got, _reference(model, spikes, True), 1e-12,
                  f'{kwargs} {budget}')
    with torch.no_grad():  # chunked without recomputation
        torch.testing.assert_close(model(spikes), got[0], rtol=0, atol=0)


def test_torch_device_path_keeps_no_hidden_activation():
    """What the backward pass keeps is the chunks' inputs (the coefficients,
    once), not the 32-channel activations of any pixel."""
    model = _model()
    coeffs = torch.randn(1, 15, 300, requires_grad=True)
    lengths = [5, 10]
    saved = {}
    for recompute in (True, False):
        saved[recompute] = []
        with torch.autograd.graph.saved_tensors_hooks(
                lambda t, into=saved[recompute]: into.append(t.numel()) or t,
                lambda t: t):
            out = band_network_backends._module_bands(
                model.band_networks[:2], coeffs, lengths, (15, 20),
                recompute=recompute, chunk_bytes=200_000)
    assert sum(saved[True]) <= coeffs.numel()
    assert sum(saved[False]) > 32 * coeffs.numel()  # the whole reference
    out.sum().backward()
    assert coeffs.grad is not None


def test_device_chunks_come_from_the_memory_budget():
    network = _model().band_networks[0]  # widths 32, 32, 1: 161 per row
    assert band_network_backends._pixels_per_chunk(
        network, 72, 4, 1 << 29) == (1 << 29) // (161 * 72 * 4)
    assert band_network_backends._pixels_per_chunk(network, 72, 8, 1) == 1


def test_device_path_cost_as_docs_state():
    """docs/wgse_speed.md's count of the device path, per chunk of the
    paper's network: aten operations (views aside) and FLOPs, against the
    arithmetic (per coefficient a forward is 2 * 3 * (32 + 32*32 + 32)
    FLOPs; training runs it twice and the backward's two products per
    convolution, but no input gradient of the first)."""
    from torch.utils._python_dispatch import TorchDispatchMode
    from torch.utils.flop_counter import FlopCounterMode

    class Operations(TorchDispatchMode):
        def __init__(self):
            super().__init__()
            self.names = []

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            if not func.is_view:
                self.names.append(str(func.overloadpacket))
            return func(*args, **(kwargs or {}))

    network = _model().band_networks[0]
    pixels, length = 40, 7
    coeffs = torch.randn(1, length, 2 * pixels)
    budget = pixels * 161 * length * 4  # two chunks of 40 pixels
    forward = 2 * 3 * (32 + 32 * 32 + 32)
    for train, flops_per_coefficient in ((False, forward),
                                         (True, 4 * forward - 2 * 3 * 32)):
        operations, flops = Operations(), FlopCounterMode(display=False)
        with flops, operations, torch.set_grad_enabled(train):
            out = band_network_backends._module_bands(
                [network], coeffs, [length], (1, 2 * pixels), True, budget)
            if train:
                out.backward(torch.ones_like(out))
        counts = {name: operations.names.count(name)
                  for name in set(operations.names)}
        per_chunk = {'aten.convolution': 3, 'aten.relu': 3}
        if train:
            per_chunk = {name: 2 * count for name, count in per_chunk.items()}
            per_chunk.update({'aten.convolution_backward': 3,
                              'aten.threshold_backward': 3})
        for name, count in per_chunk.items():
            assert counts.pop(name) == 2 * count, name
        # the residual add (per chunk, once a pass), and from the second
        # chunk on the 6 parameter gradients accumulated (in place or not)
        adds = counts.pop('aten.add', 0) + counts.pop('aten.add_', 0)
        assert adds == 2 * (2 if train else 1) + (6 if train else 0)
        # the chunks' and the bands' concatenations
        assert counts.pop('aten.cat') == 2
        assert set(counts) <= {'aten.ones_like', 'aten.clone',
                               'aten.copy_', 'aten.detach', 'aten.empty'}
        assert flops.get_total_flops() == \
            flops_per_coefficient * coeffs.numel()


def test_torch_device_path_peak_memory(monkeypatch, tmp_path):
    """docs/wgse_speed.md's bound, measured by the profiler's memory
    timeline on CPU tensors: WGSE forward+backward on the device path
    peaks within its chunk budget plus 7x the float32 spikes (measured
    6.1x) plus what does not grow with the input, where keeping every
    activation (``'reference'``) takes many times that."""
    import json

    from torch.profiler import ProfilerActivity, profile

    from wgse_mmseg.core.wavelets import band_lengths

    budget = 1 << 21
    monkeypatch.setitem(band_network_backends.BACKENDS, 'torch',
                        _device_path(budget))
    spikes = _spikes(1, 129, 16, 32)
    peaks = {}
    for backend in ('torch', 'reference'):
        model = _model(backend=backend)
        with profile(activities=[ProfilerActivity.CPU], profile_memory=True,
                     with_stack=True, record_shapes=True) as prof:
            model(spikes).square().mean().backward()
        path = str(tmp_path / f'{backend}.json')
        with warnings.catch_warnings():  # deprecated in favour of CUDA's
            warnings.simplefilter('ignore', FutureWarning)
            prof.export_memory_timeline(path, device='cpu')
        with open(path) as f:
            _, sizes = json.load(f)
        peaks[backend] = max(sum(s) for s in sizes)
    # besides: the analysis and synthesis matrices, the parameters, their
    # gradients and one temporary each
    steps = spikes.shape[1]
    fixed = 4 * (2 * steps * sum(band_lengths(steps, 'db8', 5, 'zero')) +
                 3 * sum(p.numel() for p in model.parameters()))
    assert peaks['torch'] <= budget + 7 * 4 * spikes.numel() + fixed
    assert peaks['reference'] > 4 * peaks['torch']
