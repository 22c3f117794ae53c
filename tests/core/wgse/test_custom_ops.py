"""The CPU band-network kernels as torch custom ops: torch.library's own
checks of their schemas, fake (meta) kernels and autograd registrations,
and torch.compile of WGSE with no graph break and eager's results."""
import pytest
import torch

from wgse_mmseg.core.wgse import WGSE, compiled_band_networks, wgse

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
