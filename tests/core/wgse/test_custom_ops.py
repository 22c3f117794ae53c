"""The band-network kernels as torch custom ops (the CPU kernels', and the
Triton kernels' ``triton_op``s in triton's interpreter): torch.library's
own checks of their schemas, fake (meta) kernels and autograd
registrations, and torch.compile of WGSE with no graph break and eager's
results."""
import pytest
import torch

from wgse_mmseg.core.wgse import (WGSE, compiled_band_networks,
                                  triton_band_networks, wgse)

needs_compiled = pytest.mark.skipif(
    compiled_band_networks.unavailable() is not None,
    reason=str(compiled_band_networks.unavailable()))


def _params(lengths, dtype, hidden=32):
    """One paper-shaped band network per band: ``[W_1, b_1, ...]``."""
    shapes = [(hidden, 1, 3), (hidden,), (hidden, hidden, 3), (hidden,),
              (1, hidden, 3), (1,)]
    return [(torch.randn(shape, dtype=dtype) * 0.3).requires_grad_()
            for _ in lengths for shape in shapes]


RESIDUALS = [-1, 0, -1]  # conv 1->H, H->H plus the input, H->1
LENGTHS = [4, 3]


@pytest.mark.parametrize('input_grad', [False, True])
def test_the_torch_kernel_passes_opcheck(input_grad):
    torch.manual_seed(0)
    coeffs = torch.randn(5, sum(LENGTHS), dtype=torch.float64,
                         requires_grad=input_grad)
    torch.library.opcheck(
        torch.ops.wgse_mmseg.torch_band_networks,
        (coeffs, LENGTHS, RESIDUALS, 1, _params(LENGTHS, torch.float64)))


@needs_compiled
def test_the_compiled_kernel_passes_opcheck():
    torch.manual_seed(0)
    coeffs = torch.randn(5, sum(LENGTHS))
    torch.library.opcheck(
        torch.ops.wgse_mmseg.compiled_band_networks,
        (coeffs, LENGTHS, RESIDUALS, _params(LENGTHS, torch.float32)),
        # its float32 kernel and float64 sums differ from autograd's
        # float32 in the last bits
        atol=1e-4, rtol=1e-4)


def test_the_fake_kernels_give_the_gradients_shapes_on_meta_tensors():
    coeffs = torch.empty(7, sum(LENGTHS), device='meta')
    params = [p.detach().to('meta')
              for p in _params(LENGTHS, torch.float32)]
    grads = torch.ops.wgse_mmseg.torch_band_networks_backward(
        coeffs, coeffs, LENGTHS, RESIDUALS, 1, params, True)
    assert [g.shape for g in grads] == [coeffs.shape] + [
        p.shape for p in params]
    assert torch.ops.wgse_mmseg.compiled_band_networks(
        coeffs, LENGTHS, RESIDUALS, params).shape == coeffs.shape


def test_the_transform_is_marked_as_assume_constant_result_marks():
    marked = torch.compiler.assume_constant_result(lambda: None)
    assert marked._dynamo_marked_constant is \
        wgse._transform._dynamo_marked_constant


@pytest.mark.long(60)
@needs_compiled
def test_compiled_wgse_has_no_graph_break_and_eager_results():
    torch.manual_seed(0)
    spikes = (torch.rand(2, 21, 3, 4) < 0.4).float()
    for backend in ('torch', 'compiled', 'auto'):
        torch._dynamo.reset()
        model = WGSE(backend=backend, level=2)
        explained = torch._dynamo.explain(model)(spikes)
        assert explained.graph_break_count == 0, (
            backend, [b.reason for b in explained.break_reasons])
    # forward and backward, compiled with the graph whole
    compiled = torch.compile(model, fullgraph=True)
    out = compiled(spikes)
    out.square().sum().backward()
    got = [p.grad.clone() for p in model.parameters()]
    model.zero_grad()
    expected = model(spikes)
    expected.square().sum().backward()
    torch.testing.assert_close(out, expected, rtol=1e-4, atol=1e-5)
    for grad, param in zip(got, model.parameters()):
        torch.testing.assert_close(grad, param.grad, rtol=1e-3, atol=1e-5)
    spikes[0, 0, 0, 0] = float('nan')
    with pytest.raises(RuntimeError, match='WGSE: spikes holds non-finite'):
        compiled(spikes)


# The Triton kernels' ops, in triton's interpreter on CPU tensors (see
# tests/conftest.py): the ops run, their fake kernels agree with them, and
# torch.compile's graph capture keeps them in one graph. AOTAutograd, which
# traces an op's body (the kernels' launches) with fake tensors, needs a
# GPU: the interpreter cannot read fake tensors.

TRITON_LENGTHS = [5, 3]


def _triton_inputs(input_grad=False):
    torch.manual_seed(0)
    coeffs = torch.randn(2, sum(TRITON_LENGTHS), 19,
                         requires_grad=input_grad)
    params = [p.detach().requires_grad_()
              for p in _params(TRITON_LENGTHS, torch.float32, hidden=16)]
    return coeffs, params


def _triton_args(coeffs, params, launch=(0, 0, 0, 0, 0, 0)):
    return (coeffs, TRITON_LENGTHS, params, 'ieee', list(launch), False)


@pytest.mark.needs_triton
def test_the_triton_ops_are_defined_once_with_their_schemas():
    triton_band_networks.define_ops()
    triton_band_networks.define_ops()  # a second call defines nothing
    forward = torch.ops.wgse_mmseg.triton_band_networks.default._schema
    backward = \
        torch.ops.wgse_mmseg.triton_band_networks_backward.default._schema
    assert [a.name for a in forward.arguments] == [
        'coeffs', 'lengths', 'params', 'precision', 'launch',
        'output_grad_is_scratch']
    assert len(forward.returns) == 2
    assert [a.name for a in backward.arguments] == [
        'coeffs', 'd3', 'params', 'lengths', 'precision', 'input_grad',
        'launch', 'slots']


@pytest.mark.long(60)
@pytest.mark.needs_triton
@pytest.mark.parametrize('input_grad', [False, True])
def test_the_triton_op_passes_opcheck_in_the_interpreter(input_grad):
    triton_band_networks.define_ops()
    coeffs, params = _triton_inputs(input_grad)
    torch.library.opcheck(
        torch.ops.wgse_mmseg.triton_band_networks,
        _triton_args(coeffs, params),
        test_utils=('test_schema', 'test_autograd_registration',
                    'test_faketensor'))


@pytest.mark.needs_triton
@pytest.mark.parametrize('input_grad', [False, True])
def test_the_triton_fake_kernels_give_the_kernels_shapes_and_dtypes(
        input_grad):
    triton_band_networks.define_ops()
    coeffs, params = _triton_inputs()
    real = torch.ops.wgse_mmseg.triton_band_networks(
        *_triton_args(coeffs.detach(), [p.detach() for p in params]))
    meta = [p.detach().to('meta') for p in params]
    fake = torch.ops.wgse_mmseg.triton_band_networks(
        *_triton_args(coeffs.to('meta'), meta))
    assert [(t.shape, t.dtype) for t in fake] == [
        (coeffs.shape, torch.float32), (coeffs.shape, torch.uint8)]
    assert [(t.shape, t.dtype) for t in real] == [
        (t.shape, t.dtype) for t in fake]
    d3 = torch.randn_like(coeffs)
    args = (TRITON_LENGTHS, 'ieee', input_grad, [0, 0, 0], 4)
    real = torch.ops.wgse_mmseg.triton_band_networks_backward(
        coeffs.detach(), d3, [p.detach() for p in params], *args)
    fake = torch.ops.wgse_mmseg.triton_band_networks_backward(
        coeffs.to('meta'), d3.to('meta'), meta, *args)
    per_band = sum(p.numel() for p in params[:6])
    assert [t.shape for t in fake] == [coeffs.shape] * input_grad + [
        (per_band, )] * len(TRITON_LENGTHS)
    assert [(t.shape, t.dtype) for t in real] == [
        (t.shape, t.dtype) for t in fake]


@pytest.mark.long(120)
@pytest.mark.needs_triton
def test_compiled_wgse_on_triton_has_no_graph_break_and_torch_results():
    torch.manual_seed(0)
    spikes = (torch.rand(1, 21, 3, 5) < 0.4).float()
    torch._dynamo.reset()
    model = WGSE(backend='triton', level=2, hidden_channels=16)
    explained = torch._dynamo.explain(model)(spikes)
    assert explained.graph_break_count == 0, [
        b.reason for b in explained.break_reasons]
    compiled = torch.compile(model, backend='eager', fullgraph=True)
    out = compiled(spikes)
    out.square().sum().backward()
    got = [p.grad.clone() for p in model.parameters()]
    # the plain torch implementation of the same weights
    reference = WGSE(backend='torch', level=2, hidden_channels=16)
    reference.load_state_dict(model.state_dict())
    expected = reference(spikes)
    expected.square().sum().backward()
    torch.testing.assert_close(out, expected, rtol=1e-4, atol=1e-5)
    for grad, param in zip(got, reference.parameters()):
        torch.testing.assert_close(grad, param.grad, rtol=1e-3, atol=1e-5)
