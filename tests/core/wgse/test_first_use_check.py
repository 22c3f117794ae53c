"""The first-use check of a device kernel (``first_use_check``), driven on
the CPU: stand-ins for the Triton backend that claim the CPU and fail in
each way a compiled kernel can (compile error, wrong output, wrong
gradient, NaN, one bad launch entry), one that is right, and the real
Triton kernel in triton's interpreter (``TRITON_INTERPRET=1``, set in
``conftest.py``)."""
import logging

import mmengine.logging
import pytest
import torch

from wgse_mmseg.core.wgse import WGSE, band_network_backends, \
    first_use_check, triton_launch_choices

pytestmark = pytest.mark.usefixtures('single_thread')


class _WrongGradient(torch.autograd.Function):
    """Identity forward; the gradient scaled by 1.5."""

    @staticmethod
    def forward(ctx, x):
        return x.clone()

    @staticmethod
    def backward(ctx, grad):
        return 1.5 * grad


class _StandIn(band_network_backends.TorchBackend):
    """The ``torch`` backend posing as a checked GPU kernel on the CPU,
    broken as ``fault`` says on the launch entries of ``broken``."""

    name = 'triton'
    first_use_check = True

    def __init__(self, fault=None, broken=(0, 1)):
        self.fault, self.broken, self.calls = fault, broken, 0

    def check_launches(self, passes, precision):
        return [(dict(entry=entry), band_network_backends._input_grad(passes))
                for entry in (0, 1)]

    def run(self, networks, coeffs, lengths, spatial,
            output_grad_is_scratch=False, entry=0):
        self.calls += 1
        out = super().run(networks, coeffs, lengths, spatial)
        if entry not in self.broken or self.fault is None:
            return out
        if self.fault == 'compile':
            raise RuntimeError('CompilationError: at 12:4: (stand-in)')
        if self.fault == 'output':
            return out + 0.9
        if self.fault == 'gradient':
            return _WrongGradient.apply(out)
        assert self.fault == 'nan'
        return out + torch.where(torch.arange(out.numel()).view_as(out) == 5,
                                 float('nan'), 0.0)


@pytest.fixture
def log(monkeypatch):
    """Fresh check results; the log lines (level, message) it writes."""
    monkeypatch.setattr(first_use_check, '_RESULTS', {})
    lines = []
    monkeypatch.setattr(mmengine.logging, 'print_log',
                        lambda msg, logger=None, level=logging.INFO:
                        lines.append((level, msg)))
    return lines


def _install(monkeypatch, backend):
    """``backend`` as 'triton', and 'auto''s first choice on the CPU."""
    monkeypatch.setitem(band_network_backends.BACKENDS, 'triton', backend)
    monkeypatch.setitem(band_network_backends._AUTO, 'cpu', 'triton')


def _spikes(steps=12, seed=1):
    generator = torch.Generator().manual_seed(seed)
    return (torch.rand(2, steps, 3, 5, generator=generator) < 0.4).float()


def _torch_result(model, spikes):
    torch_model = WGSE(wavelet=model.wavelet, level=model.level,
                       backend='torch')
    torch_model.load_state_dict(model.state_dict())
    return torch_model(spikes)


@pytest.mark.parametrize('fault, what', [
    ('compile', 'raised (entry=0, input gradient False): RuntimeError: '
                'CompilationError'),
    ('output', 'output disagrees'),
    ('gradient', 'gradient'),
    ('nan', 'output NaN or Inf'),
])
def test_auto_falls_back_and_logs_once(monkeypatch, log, fault, what):
    stand_in = _StandIn(fault)
    _install(monkeypatch, stand_in)
    torch.manual_seed(0)
    model = WGSE(wavelet='haar', level=2)
    spikes = _spikes()
    for _ in range(2):  # the second forward pass neither checks nor logs
        out = model(spikes)
    assert model.backend_in_use == 'torch'
    check = model.backend_check
    assert not check.passed and what in check.failure
    assert check.device == 'cpu' and 'bands [3, 3, 6]' in check.variant
    torch.testing.assert_close(out, _torch_result(model, spikes),
                               rtol=0, atol=0)
    assert len(log) == 2  # the start, then the outcome
    assert log[0][0] == logging.INFO
    assert log[0][1].startswith(
        f"WGSE: checking the 'triton' band-network kernel on cpu "
        f"({check.variant}) against the 'torch' backend in float64 before "
        f"its first use")
    level, message = log[1]
    assert level == logging.WARNING
    for part in ('FAILED its first-use check', 'on cpu', what,
                 'largest relative error', "runs the 'torch' backend",
                 first_use_check.REPORT_TO):
        assert part in message
    # named explicitly, it raises with the same message
    model.backend = 'triton'
    with pytest.raises(first_use_check.FirstUseCheckFailed,
                       match="backend='triton' was named") as error:
        model(spikes)
    assert check.message() in str(error.value)


def test_every_launch_entry_is_checked(monkeypatch, log):
    _install(monkeypatch, _StandIn('output', broken=(1, )))
    model = WGSE(wavelet='haar', level=1)
    model(_spikes())
    assert model.backend_in_use == 'torch'
    assert '(entry=1, input gradient False)' in model.backend_check.failure


@pytest.mark.parametrize('precision', ['ieee', 'tf32', 'fp16', 'bf16'])
@pytest.mark.parametrize('passes, input_grad', list(zip(
    first_use_check.PASSES, (None, False, True))))
def test_the_triton_check_runs_what_the_call_launches(passes, input_grad,
                                                      precision):
    """Every forward entry, and the backward entries chosen for the call's
    input gradient and precision where it runs the backward pass: no
    compile of a kernel the call does not run (the check's compiles are a
    machine's first wait: training's compiles no backward entry for the
    input gradient, inference's no backward at all)."""
    launches = band_network_backends.TritonBackend().check_launches(
        passes, precision)
    assert {grad for _, grad in launches} == {input_grad}
    assert {launch['forward_config'] for launch, _ in launches} == set(
        triton_launch_choices.FORWARD_CONFIGS)
    assert {launch.get('backward_config') for launch, _ in launches} == (
        {None} if input_grad is None else
        set(triton_launch_choices.backward_configs(input_grad, precision)))
    assert len(launches) == len(set(
        tuple(launch.items()) for launch, _ in launches))


@pytest.mark.parametrize('call, passes', [
    ('inference', 'forward'),
    ('training', 'forward and backward'),
    ('input gradient',
     "forward and backward with the coefficients' gradient"),
])
def test_the_check_follows_what_the_call_runs(monkeypatch, log, call,
                                              passes):
    seen = []

    class Noting(_StandIn):
        def check_launches(self, passes, precision):
            seen.append(passes)
            return super().check_launches(passes, precision)

    _install(monkeypatch, Noting())
    model = WGSE(wavelet='haar', level=1)
    spikes = _spikes()
    if call == 'inference':
        with torch.no_grad():
            model(spikes)
    else:
        model(spikes.requires_grad_(call == 'input gradient'))
    assert seen == [passes]
    assert model.backend_check.variant.endswith(', ' + passes)
    if call == 'training':  # a frozen WGSE in training: no gradient
        model.requires_grad_(False)
        model(spikes)
        assert seen == [passes, 'forward']


def test_a_gradient_wrong_only_without_the_input_gradient(monkeypatch, log):
    """Parameter gradients alone (coefficients that need none: WGSE in
    training) are compared too."""

    class ParameterGradientsOff(_StandIn):
        def run(self, networks, coeffs, lengths, spatial,
                output_grad_is_scratch=False, entry=0):
            out = super().run(networks, coeffs, lengths, spatial,
                              entry=entry)
            return out if coeffs.requires_grad else _WrongGradient.apply(out)

    _install(monkeypatch, ParameterGradientsOff())
    model = WGSE(wavelet='haar', level=1)
    model(_spikes())
    assert model.backend_in_use == 'torch'
    failure = model.backend_check.failure
    assert 'gradient of band' in failure and 'input gradient False' in failure


def test_a_kernel_that_agrees_runs_after_one_check_per_variant(
        monkeypatch, log):
    stand_in = _StandIn()
    _install(monkeypatch, stand_in)
    model = WGSE(wavelet='haar', level=2)
    out = model(_spikes())
    assert model.backend_in_use == 'triton'
    check = model.backend_check
    assert check.passed and check.failure is None
    assert 0 <= check.max_error <= first_use_check.TOLERANCE
    # 2 launch entries, one call each, then the call itself
    assert stand_in.calls == 2 + 1
    torch.testing.assert_close(out, _torch_result(model, _spikes()))
    assert [level for level, _ in log] == [logging.INFO] * 2
    assert 'WGSE: checking' in log[0][1]
    assert 'passed its first-use check' in log[1][1]
    model(_spikes())
    assert stand_in.calls == 4 and len(log) == 2  # checked once
    model(_spikes(steps=20))  # other band lengths: another variant
    assert stand_in.calls == 4 + 3 and len(log) == 4
    with torch.no_grad():  # the forward pass alone: checked on its own
        model(_spikes())
    assert stand_in.calls == 7 + 3 and len(log) == 6


def test_backends_without_a_kernel_of_their_own_are_not_checked(log):
    model = WGSE(wavelet='haar', level=1)
    model(_spikes())
    assert model.backend_in_use in ('compiled', 'torch')
    assert model.backend_check is None and not log


def test_relative_errors():
    want = [torch.tensor([2.0, -4.0]), torch.tensor([1e-3, 0.0])]
    got = [torch.tensor([2.0, -3.0]), torch.tensor([2e-3, 0.0])]
    # 1/4; the near-zero tensor against a hundredth of the largest (4)
    assert first_use_check.relative_errors(got, want) == pytest.approx(
        [0.25, 1e-3 / 4e-2])
    got[1][1] = float('nan')
    assert first_use_check.relative_errors(got, want)[1] == float('inf')


@pytest.mark.needs_triton
@pytest.mark.parametrize('autocast', [None, torch.float16, torch.bfloat16])
@pytest.mark.parametrize('major', [8, 10])
@pytest.mark.parametrize('call', ['inference', 'training', 'input gradient'])
def test_the_real_triton_kernel_passes_in_the_interpreter(monkeypatch, log,
                                                          autocast, major,
                                                          call):
    """The check around the real kernel: every launch entry of the call
    (the forward alone, with the backward, with the input gradient) against
    float64, at TF32 and with fp16 and bf16 operands (under autocast; the
    check's problem is exact in both, so a right kernel agrees to float32's
    accumulation), with the forward's conv1 as a GPU of compute capability
    ``major`` computes it (at TF32 on tensor cores on a B200, 10, with
    multiply-adds before)."""

    class CheckedTriton(band_network_backends.TritonBackend):
        first_use_check = True
        check_pixels = 17  # a partial tile of every entry

    assert not band_network_backends.TritonBackend().first_use_check
    _install(monkeypatch, CheckedTriton())
    choice = triton_launch_choices.conv1_on_tensor_cores
    chosen = []

    def on_this_gpu(precision, interpreter_major):
        chosen.append(choice(precision, major))
        return chosen[-1]

    monkeypatch.setattr(triton_launch_choices, 'conv1_on_tensor_cores',
                        on_this_gpu)
    model = WGSE(wavelet='haar', level=1)
    spikes = _spikes(steps=6)[:1, :, :1]
    spikes.requires_grad_(call == 'input gradient')
    with torch.autocast('cpu', dtype=autocast or torch.bfloat16,
                        enabled=autocast is not None), \
            torch.set_grad_enabled(call != 'inference'):
        out = model(spikes)
    assert model.backend_in_use == 'triton', model.backend_check
    check = model.backend_check
    assert check.passed, check.message()
    assert check.variant.startswith('precision ' + {
        None: 'tf32', torch.float16: 'fp16',
        torch.bfloat16: 'bf16'}[autocast])
    assert check.max_error <= first_use_check.TOLERANCE
    assert set(chosen) == {autocast is not None or major == 10}
    if autocast is None:
        torch.testing.assert_close(out, _torch_result(model, spikes),
                                   rtol=1e-5, atol=1e-5)
    assert check.variant.endswith(
        ', ' + first_use_check.PASSES[['inference', 'training',
                                       'input gradient'].index(call)])


@pytest.mark.long(60)
@pytest.mark.needs_triton
@pytest.mark.parametrize('call', ['training', 'input gradient'])
@pytest.mark.parametrize('precision', ['ieee', 'tf32', 'fp16', 'bf16'])
def test_the_papers_network_passes_its_check_in_the_interpreter(
        monkeypatch, log, precision, call):
    """The check of the paper's network (db8, 5 levels, 32 channels) at T =
    129, whose bands are 18, 18, 22, 29, 43 and 72 coefficients long, over
    a partial tile of every launch entry, at every precision: the
    kernels' paths at the band lengths training runs, against float64 on
    the check's exact problem (the test above runs a one-level Haar
    network, bands of 3)."""

    class CheckedTriton(band_network_backends.TritonBackend):
        first_use_check = True
        check_pixels = 17

    _install(monkeypatch, CheckedTriton())
    monkeypatch.setattr(torch.backends.cudnn, 'allow_tf32',
                        precision != 'ieee')
    model = WGSE()  # the paper's
    spikes = _spikes(steps=129)[:1, :, :1, :1]
    spikes.requires_grad_(call == 'input gradient')
    autocast = dict(fp16=torch.float16, bf16=torch.bfloat16).get(precision)
    with torch.autocast('cpu', dtype=autocast or torch.bfloat16,
                        enabled=autocast is not None):
        model(spikes).sum().backward()
    check = model.backend_check
    assert model.backend_in_use == 'triton', check
    assert check.passed, check.message()
    assert check.variant.startswith(f'precision {precision}')
    assert 'hidden_channels=32 ' in check.variant
    assert 'bands [18, 18, 22, 29, 43, 72]' in check.variant


@pytest.mark.parametrize('hidden, steps', [(32, 129), (16, 41)])
def test_the_problem_is_exact_at_every_precision(hidden, steps):
    """What the check's one tolerance rests on: on its problem, every
    operand of the kernels' tensor-core products is exact in the precision
    it is rounded to: the H x H layer's input, weight and output gradient
    and conv1's input and weight in bf16 and fp16 (so in TF32 too), the
    gradient at conv1's output (the backward's sums for conv1's weight, on
    TF32 operands at every tensor-core precision) in TF32; and no
    pre-activation is zero, so rounding moves no ReLU decision."""
    from wgse_mmseg.core.wavelets import band_lengths
    model = WGSE(hidden_channels=hidden)
    lengths = band_lengths(steps, model.wavelet, model.level, model.mode)
    nets, coeffs, weights = first_use_check._problem(
        model.band_networks, lengths,
        band_network_backends.TritonBackend.check_pixels, torch.device('cpu'))
    seen = {'operands': [], 'tf32 operands': [], 'pre-activations': []}
    for net in nets:
        layer = net.residual_layers[0]
        for conv in (layer.conv_a, layer.conv_b):
            conv.register_forward_hook(
                lambda m, args, out: seen['operands'].extend([args[0],
                                                              m.weight]))
        layer.conv_b.register_full_backward_hook(
            lambda m, grad_in, grad_out: seen['operands'].append(
                grad_out[0]))
        layer.conv_a.register_full_backward_hook(
            lambda m, grad_in, grad_out: seen['tf32 operands'].append(
                grad_out[0]))
        for conv in (layer.conv_a, net.output_convs[0]):
            conv.register_forward_hook(
                lambda m, args, out: seen['pre-activations'].append(out))
        # conv_b's pre-activation adds the residual input
        layer.register_forward_hook(
            lambda m, args, out: seen['pre-activations'].append(
                m.conv_b._conv_forward(torch.relu(m.conv_a._conv_forward(
                    args[0], m.conv_a.weight, m.conv_a.bias)),
                    m.conv_b.weight, m.conv_b.bias) + args[0]))
    coeffs.requires_grad_(True)
    out = band_network_backends.BACKENDS['reference'].run(
        nets, coeffs, lengths, (1, 67))
    (out * weights).sum().backward()
    assert len(seen['operands']) == 5 * len(nets)
    for tensor in seen['operands']:
        for dtype in (torch.bfloat16, torch.float16):
            assert torch.equal(tensor.to(dtype).double(), tensor)
    assert len(seen['tf32 operands']) == len(nets)
    for tensor in seen['tf32 operands']:
        # TF32 keeps 11 significant bits: 2^11 times the mantissa in [0.5,
        # 1) is an integer
        mantissa, _ = torch.frexp(tensor)
        assert torch.equal(mantissa * 2 ** 11, (mantissa * 2 ** 11).round())
    for tensor in seen['pre-activations']:
        assert (tensor != 0).all()
    # both sides of every ReLU are visited, in every band
    assert all(0.01 < (t > 0).double().mean() < 0.99
               for t in seen['pre-activations'])
