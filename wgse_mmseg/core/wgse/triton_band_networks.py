"""WGSE's 1-D band networks as a Triton kernel (CUDA).

Runs the paper's band network (``num_blocks=1``: conv ``1 -> H``, conv
``H -> H`` plus the input, conv ``H -> 1``, each followed by ReLU; kernel 3)
for every pixel, a tile of pixels per program (the launch entries of
:mod:`~wgse_mmseg.core.wgse.triton_launch_choices`), the weights read once
per program and the ``H x H`` layer on tensor cores (``tl.dot``). The
backward pass recomputes each tile's activations while it streams the
gradient, so nothing of size ``pixels x H`` is ever kept: the only memory
beyond the input, output and their gradients is the forward's mask of
where the output is positive (a byte a coefficient) and one row of
parameter-gradient sums per program.
Kernels: :mod:`.triton_band_kernels`.

Precision of the tensor-core products
(:func:`~.triton_launch_choices.dot_precision`): under
autocast their operands are rounded to its dtype (fp16 or bf16); otherwise
TF32 where ``torch.backends.cudnn.allow_tf32`` allows it (the flag torch
applies to convolutions, on by default), else full float32. Every
accumulation is float32. The tolerances against float64 that the tests
hold are :data:`TOLERANCES`.

Triton launches a kernel on torch's current device and stream, not on its
tensors' device: every launch here is made with the coefficients' device
current (:func:`on_device_of`), so that a model on ``cuda:1`` while
``cuda:0`` is current runs there, ordered with the stream its inputs were
made on.

The two passes are torch custom ops made with ``torch.library.triton_op``
(:data:`FORWARD_OP`, :data:`BACKWARD_OP`; each launch through
``torch.library.wrap_triton``), with fake kernels and the forward's
autograd registration, so that ``torch.compile`` of a model holding WGSE
keeps them in its graph (no graph break) and Inductor sees the kernels.
They are defined at the first call (:func:`define_ops`): ``triton_op``
reads its function's source with Inductor's helpers, seconds of imports
that a process which never runs the kernel does not pay.

Triton's interpreter (``TRITON_INTERPRET=1`` in the environment before
triton is first imported) runs the same kernels on CPU tensors; the tests
use it, since CI has no GPU. There ``wrap_triton`` hands back the
interpreted kernel itself, so the ops run eagerly and under
``torch.compile``'s graph capture (``backend='eager'``), but not where
AOTAutograd traces the ops' bodies with fake tensors (which the
interpreter cannot read).
"""
import contextlib
import os
from typing import List, NamedTuple, Optional, Sequence, Tuple

import torch
from torch import Tensor

from ..kernel_choices import HIDDEN_CHANNELS, TOLERANCES
from . import triton_launch_choices as launch_choices
from .triton_launch_choices import LaunchConfig

try:
    import triton

    from . import triton_band_kernels as kernels
    _IMPORT_ERROR = None
except ImportError as error:  # triton is not installed (CPU-only torch)
    triton = kernels = None
    _IMPORT_ERROR = str(error)

__all__ = []


def interpreting() -> bool:
    """Whether triton runs kernels in its CPU interpreter."""
    return os.environ.get('TRITON_INTERPRET', '0') not in ('', '0')


def _interpreter_reads_scalar_bounds() -> None:
    """triton 3.6's interpreter holds a scalar as a one-element array and
    turns it into a Python ``int`` (the kernels' ``range(0, length + 2)``,
    ``length`` read at run time) with ``int(array)``, which NumPy 2 refuses
    for an array of one dimension; the compiled kernels take such bounds.
    Under the interpreter, read the one element instead (once a process)."""
    from triton.runtime import interpreter
    original = interpreter._patch_lang_tensor
    if getattr(original, 'reads_scalar_bounds', False):
        return

    def patch(tensor, scope):
        original(tensor, scope)
        scope.set_attr(tensor, '__index__',
                       lambda self: int(self.handle.data.reshape(-1)[0]))

    patch.reads_scalar_bounds = True
    interpreter._patch_lang_tensor = patch


if triton is not None and interpreting():
    _interpreter_reads_scalar_bounds()


def unavailable() -> Optional[str]:
    """Why the Triton kernel cannot run in this installation, or ``None``."""
    if triton is None:
        return f'triton does not import ({_IMPORT_ERROR})'
    return None


def unsupported_network(dim: int, kernel_size: int, hidden_channels: int,
                        num_blocks: int) -> Optional[str]:
    """Why the kernel cannot run a band network of this shape, or ``None``."""
    if dim != 1:
        return f'it runs dim=1 band networks, not dim={dim}'
    if kernel_size != 3 or num_blocks != 1:
        return (f'it runs the paper\'s network (kernel_size=3, '
                f'num_blocks=1), not kernel_size={kernel_size}, '
                f'num_blocks={num_blocks}')
    if hidden_channels not in HIDDEN_CHANNELS:
        return (f'it runs hidden_channels in {HIDDEN_CHANNELS}, not '
                f'{hidden_channels}')
    return None


def unsupported_tensor(coeffs: Tensor) -> Optional[str]:
    """Why the kernel cannot run on ``coeffs``, or ``None``: float32 CUDA
    tensors (CPU tensors under the interpreter)."""
    device = 'cpu' if interpreting() else 'cuda'
    if coeffs.device.type != device:
        return (f'it runs on {device} tensors' +
                ('' if interpreting() else
                 ' (CPU tensors only under TRITON_INTERPRET=1)'))
    if coeffs.dtype != torch.float32:
        return f'it runs float32, not {coeffs.dtype}'
    return None


class BandKernelInputs(NamedTuple):
    """What both kernels read besides the coefficients: per band its length
    and first row ``(bands,)`` int32, and the six parameters stacked over
    the bands (:func:`parameter_shapes` after the band), float32."""
    lengths: Tensor
    offsets: Tensor
    params: Tuple[Tensor, ...]
    #: the lengths as Python ints: the backward's work division reads them
    #: without waiting on the device
    band_lengths: Tuple[int, ...]

    @property
    def hidden(self) -> int:
        """The bands' hidden channels."""
        return self.params[0].shape[1]


def parameter_shapes(hidden: int) -> List[Tuple[int, ...]]:
    """The shapes of one band's parameters, conv1, conv2, conv3 each
    ``(weight, bias)``, for ``hidden`` channels."""
    return [(hidden, 1, 3), (hidden, ), (hidden, hidden, 3), (hidden, ),
            (1, hidden, 3), (1, )]


def band_kernel_inputs(lengths: Sequence[int], params: Sequence[Tensor]
                       ) -> BandKernelInputs:
    """:class:`BandKernelInputs` of bands of ``lengths`` whose parameters
    are ``params``, six a band (conv1, conv2, conv3 each weight and
    bias)."""
    device = params[0].device
    offsets = [sum(lengths[:band]) for band in range(len(lengths))]
    return BandKernelInputs(
        torch.tensor(lengths, dtype=torch.int32, device=device),
        torch.tensor(offsets, dtype=torch.int32, device=device),
        tuple(torch.stack(params[kind::6]).contiguous() for kind in range(6)),
        tuple(lengths))


def on_device_of(tensor: Tensor) -> contextlib.AbstractContextManager:
    """The context a kernel reading ``tensor`` is launched in: its CUDA
    device current (triton launches on the current device's current
    stream); nothing for a CPU tensor (the interpreter)."""
    return torch.cuda.device(tensor.device) if tensor.is_cuda else \
        contextlib.nullcontext()


def _launch_options(config: LaunchConfig) -> dict:
    """A launch's options: ``num_warps``, and ``maxnreg`` where the entry
    sets it (torch.compile's kernel wrapper passes on the options it knows
    and would take a ``maxnreg=None`` for a kernel argument)."""
    options = dict(num_warps=config.num_warps)
    if config.maxnreg is not None:
        options['maxnreg'] = config.maxnreg
    return options


def launch_forward(config: LaunchConfig, coeffs: Tensor,
                   inputs: BandKernelInputs, precision: str
                   ) -> Tuple[Tensor, Tensor]:
    """One launch of ``band_forward`` over every band of ``coeffs``
    ``(B, C, P)`` (none for an empty one): the networks' output and where
    it is positive (uint8 0 or 1), both ``(B, C, P)``."""
    out = torch.empty_like(coeffs)
    positive = torch.empty_like(coeffs, dtype=torch.uint8)
    if coeffs.numel():
        batch, columns, pixels = coeffs.shape
        tiles = triton.cdiv(pixels, config.block)
        major = 0 if interpreting() else \
            torch.cuda.get_device_capability(coeffs.device)[0]
        kernel = torch.library.wrap_triton(kernels.band_forward)
        with on_device_of(coeffs):
            kernel[(batch * tiles, len(inputs.lengths))](
                coeffs, out, positive, pixels, columns, tiles,
                inputs.lengths, inputs.offsets, *inputs.params,
                HIDDEN=inputs.hidden, BLOCK=config.block,
                PRECISION=precision,
                CONV1_DOT=launch_choices.conv1_on_tensor_cores(precision,
                                                               major),
                TAPS_01_AS_ONE=launch_choices.taps_as_one_product(precision,
                                                                  major),
                **_launch_options(config))
    return out, positive


def relu_gradient(grad_out: Tensor, positive: Tensor,
                  in_place: bool = False) -> Tensor:
    """``d3`` ``(B, C, P)``: the gradient at the last convolution's
    pre-activation, ``grad_out`` where ``positive`` (from
    :func:`launch_forward`) is set, else 0 (both ``(B, C, P)``). With
    ``in_place`` (``grad_out`` is a tensor nothing else reads) it is formed
    in ``grad_out``'s memory where that is contiguous: one
    coefficient-sized tensor less at the backward pass's peak."""
    keep = positive.view(torch.bool)
    if in_place and grad_out.is_contiguous():
        return torch.where(keep, grad_out, grad_out.new_zeros(()),
                           out=grad_out)
    return torch.where(keep, grad_out, 0.0).contiguous()


def launch_backward(config: LaunchConfig, coeffs: Tensor, d3: Tensor,
                    grad_coeffs: Optional[Tensor], inputs: BandKernelInputs,
                    precision: str, slots: int) -> List[Tensor]:
    """One launch of ``band_backward`` for :func:`launch_forward`'s bands,
    from ``d3`` (:func:`relu_gradient`): the input gradient into
    ``grad_coeffs`` (none if ``None``). Returns each band's
    parameter gradient, flattened and concatenated ``(P_band,)``: the sum
    of its programs' rows (``slots``: programs in all, about), then conv3's
    bias gradient, the sum of ``d3`` over the band's rows."""
    batch, columns, pixels = coeffs.shape
    tiles = batch * triton.cdiv(pixels, config.block)
    division = launch_choices.work_division(inputs.band_lengths, tiles,
                                            slots)
    work = torch.tensor(division, dtype=torch.int32, device=coeffs.device)
    partial = coeffs.new_empty(len(division),
                               sum(p[0].numel() for p in inputs.params[:5]))
    kernel = torch.library.wrap_triton(kernels.band_backward)
    with on_device_of(coeffs):
        kernel[(len(division), )](
            coeffs, d3, coeffs if grad_coeffs is None else grad_coeffs,
            partial, work, pixels, columns,
            triton.cdiv(pixels, config.block), tiles, inputs.lengths,
            inputs.offsets, *inputs.params, HIDDEN=inputs.hidden,
            BLOCK=config.block, PRECISION=precision,
            INPUT_GRAD=grad_coeffs is not None, **_launch_options(config))
    counts = [step for _, first, step in division if first == 0]
    bias3 = d3.sum(dim=(0, 2)).split(list(inputs.band_lengths))
    return [torch.cat([rows.sum(0), rows3.sum().view(1)])
            for rows, rows3 in zip(partial.split(counts), bias3)]


def backward_slots(device: torch.device, bands: int) -> int:
    """Programs the backward kernel's work is divided into: every SM's
    :data:`~.triton_launch_choices.PROGRAMS_PER_SM` on a GPU; two a band
    under the interpreter (so that its tests see programs that run several
    tiles)."""
    if interpreting():
        return 2 * bands
    return torch.cuda.get_device_properties(
        device).multi_processor_count * launch_choices.PROGRAMS_PER_SM


FORWARD_OP = 'wgse_mmseg::triton_band_networks'
BACKWARD_OP = 'wgse_mmseg::triton_band_networks_backward'
#: a call's launch entries as the ops take them: forward ``block,
#: num_warps, maxnreg``, then the backward's; ``0`` for a ``maxnreg`` not
#: set, and ``0, 0, 0`` for the default entry
NO_LAUNCH = (0, 0, 0)


def _launch_ints(config: Optional[LaunchConfig]) -> List[int]:
    if config is None:
        return list(NO_LAUNCH)
    return [config.block, config.num_warps, config.maxnreg or 0]


def _launch_config(ints: Sequence[int]) -> Optional[LaunchConfig]:
    """:func:`_launch_ints` read back (``None``: the default entry)."""
    block, num_warps, maxnreg = ints
    if (block, num_warps, maxnreg) == NO_LAUNCH:
        return None
    return LaunchConfig(block, num_warps, maxnreg or None)


def _forward_op(coeffs: Tensor, lengths: List[int], params: List[Tensor],
                precision: str, launch: List[int],
                output_grad_is_scratch: bool) -> Tuple[Tensor, Tensor]:
    """The forward kernel as a torch op: :func:`launch_forward`'s output
    and mask ``(B, C, P)`` for ``coeffs`` ``(B, C, P)`` contiguous,
    ``params`` six a band, ``launch`` (:func:`_launch_ints`, both passes';
    the forward's three first) and ``output_grad_is_scratch`` (read by the
    backward pass, :func:`triton_band_networks`)."""
    config = _launch_config(launch[:3]) or launch_choices.FORWARD_CONFIGS[0]
    return launch_forward(config, coeffs, band_kernel_inputs(lengths, params),
                          precision)


def _forward_fake(coeffs, lengths, params, precision, launch,
                  output_grad_is_scratch):
    return (torch.empty_like(coeffs),
            torch.empty_like(coeffs, dtype=torch.uint8))


def _backward_op(coeffs: Tensor, d3: Tensor, params: List[Tensor],
                 lengths: List[int], precision: str, input_grad: bool,
                 launch: List[int], slots: int) -> List[Tensor]:
    """The backward kernel as a torch op: ``[d coeffs (B, C, P)]`` where
    ``input_grad``, then each band's parameter gradient flattened
    ``(P_band,)`` (:func:`launch_backward`), from ``d3``
    (:func:`relu_gradient`), with the entry ``launch`` (three ints,
    :func:`_launch_ints`) and ``slots`` programs."""
    grad_coeffs = torch.empty_like(coeffs) if input_grad else None
    config = _launch_config(launch) or launch_choices.backward_configs(
        input_grad, precision)[0]
    totals = launch_backward(config, coeffs, d3, grad_coeffs,
                             band_kernel_inputs(lengths, params), precision,
                             slots)
    return ([grad_coeffs] if input_grad else []) + totals


def _backward_fake(coeffs, d3, params, lengths, precision, input_grad,
                   launch, slots):
    per_band = [sum(p.numel() for p in params[first:first + 6])
                for first in range(0, len(params), 6)]
    return ([torch.empty_like(coeffs)] if input_grad else []) + [
        coeffs.new_empty(size) for size in per_band]


def _setup_context(ctx, inputs, output) -> None:
    coeffs, lengths, params, precision, launch, scratch = inputs
    ctx.lengths, ctx.precision, ctx.launch = lengths, precision, launch
    ctx.output_grad_is_scratch = scratch
    # kept outside the saved tensors so that the backward pass can drop
    # it before the coefficients are made again (WGSE's hooks): the two
    # are never alive together
    ctx.positive = output[1]
    ctx.save_for_backward(coeffs, *params)
    # no zeros made for the mask's gradient (it has none) while the
    # backward pass's largest tensors are alive; the output, the one
    # differentiable, always has one when the backward pass runs
    ctx.set_materialize_grads(False)


def _backward(ctx, grad_out: Tensor, _grad_positive):
    if torch.is_grad_enabled():
        raise RuntimeError(
            "WGSE's 'triton' band-network backend has no second-order "
            "gradients (create_graph=True); the 'torch' backend has "
            "them: WGSE(backend='torch')")
    positive, ctx.positive = ctx.positive, None
    scratch = ctx.output_grad_is_scratch
    d3 = None if positive is None else relu_gradient(grad_out, positive,
                                                     scratch)
    del positive
    coeffs, *params = ctx.saved_tensors
    input_grad = ctx.needs_input_grad[0]
    if not coeffs.numel():
        return (torch.zeros_like(coeffs) if input_grad else None, None,
                [torch.zeros_like(p) for p in params], None, None, None)
    if d3 is None:
        # a second backward pass of the graph (retain_graph=True): the
        # first dropped the mask; the forward makes it again
        _, positive = torch.ops.wgse_mmseg.triton_band_networks(
            coeffs, ctx.lengths, params, ctx.precision, ctx.launch, False)
        d3 = relu_gradient(grad_out, positive, scratch)
        del positive
    found = torch.ops.wgse_mmseg.triton_band_networks_backward(
        coeffs, d3, params, ctx.lengths, ctx.precision, input_grad,
        ctx.launch[3:], backward_slots(coeffs.device, len(ctx.lengths)))
    grad_coeffs = found.pop(0) if input_grad else None
    sizes = [p.numel() for p in params[:6]]
    grads = []
    for total, band_params in zip(found, zip(*[iter(params)] * 6)):
        grads += [g.view_as(p) for g, p in
                  zip(total.split(sizes), band_params)]
    return grad_coeffs, None, grads, None, None, None


#: the ops, once :func:`define_ops` made them
_OPS: List[object] = []


def define_ops() -> None:
    """Define :data:`FORWARD_OP` and :data:`BACKWARD_OP` (``triton_op``,
    each with its fake kernel; the forward with its autograd), once a
    process. ``torch.compile`` calls it as it is and takes its result as a
    constant (it marks no graph break)."""
    if _OPS:
        return
    forward = torch.library.triton_op(FORWARD_OP, _forward_op,
                                      mutates_args=())
    forward.register_fake(_forward_fake)
    forward.register_autograd(_backward, setup_context=_setup_context)
    backward = torch.library.triton_op(BACKWARD_OP, _backward_op,
                                       mutates_args=())
    backward.register_fake(_backward_fake)
    _OPS.extend((forward, backward))


# What ``torch.compiler.assume_constant_result(define_ops)`` sets, without
# importing torch._dynamo with the module (as WGSE's transform does)
define_ops._dynamo_marked_constant = True


def triton_band_networks(coeffs: Tensor, lengths: Sequence[int],
                         weights: Sequence[Sequence[Tuple[Tensor, Tensor]]],
                         precision: str = 'ieee',
                         forward_config: Optional[LaunchConfig] = None,
                         backward_config: Optional[LaunchConfig] = None,
                         output_grad_is_scratch: bool = False) -> Tensor:
    """Run one band network per band over every pixel's coefficients.

    Args:
        coeffs: ``(B, C, P)`` float32 coefficients of ``P`` pixels, band
            after band along ``C = sum(lengths)``, on CUDA (on the CPU
            under the interpreter).
        lengths: ``L`` of each band.
        weights: per band, the three convolutions' ``(weight, bias)``:
            ``(H, 1, 3)``, ``(H, H, 3)``, ``(1, H, 3)`` and ``(H,)``,
            ``(H,)``, ``(1,)``, float32.
        precision: of the tensor-core products
            (:func:`~.triton_launch_choices.dot_precision`).
        forward_config, backward_config: the launch of each kernel; by
            default the first entry of
            :data:`~.triton_launch_choices.FORWARD_CONFIGS` and of
            :func:`~.triton_launch_choices.backward_configs` for the input
            gradient's choice and ``precision``.
        output_grad_is_scratch: the gradient that will reach the output in
            the backward pass is a tensor nothing else reads (WGSE's
            synthesis product makes a new one): ``d3`` is then formed in
            its memory (:func:`relu_gradient`), one ``(B, C, P)`` tensor
            less at the backward pass's peak. Never for a gradient a
            caller may read again (one passed to ``backward()``).

    Returns:
        ``(B, C, P)``: each band's network output in place of its input.
        Gradients flow to ``coeffs`` and every parameter (first order).
    """
    reason = unavailable() or unsupported_tensor(coeffs)
    if reason:
        raise ValueError(f'the Triton band network kernel cannot run here: '
                         f'{reason}')
    if precision not in TOLERANCES:
        raise ValueError(f'precision must be one of {list(TOLERANCES)}, got '
                         f'{precision!r}')
    if coeffs.dim() != 3 or len(weights) != len(lengths) or \
            sum(lengths) != coeffs.shape[1] or min(lengths, default=1) < 1:
        raise ValueError(
            f'{len(weights)} band networks and bands of lengths '
            f'{list(lengths)} do not fit coefficients shaped '
            f'{tuple(coeffs.shape)} (B, C, P)')
    hidden = weights[0][0][0].shape[0]
    reason = unsupported_network(1, 3, hidden, 1)
    if reason:
        raise ValueError(f'the Triton band network kernel: {reason}')
    expected = parameter_shapes(hidden)
    params = [t for band in weights for layer in band for t in layer]
    for band in weights:
        shapes = [tuple(t.shape) for layer in band for t in layer]
        if shapes != expected:
            raise ValueError(f'the Triton kernel runs conv 1->H, H->H, H->1 '
                             f'(kernel 3) band networks: expected parameter '
                             f'shapes {expected}, got {shapes}')
    if any(p.dtype != torch.float32 or p.device != coeffs.device
           for p in params):
        raise ValueError('the Triton kernel needs float32 parameters on '
                         f'{coeffs.device}')
    for name, config, allowed in (
            ('forward_config', forward_config,
             launch_choices.FORWARD_CONFIGS),
            ('backward_config', backward_config,
             launch_choices.backward_configs())):
        if config is not None and config not in allowed:
            raise ValueError(f'{name} must be one of {list(allowed)} (the '
                             f'entries compiled and tested), got {config!r}')
    define_ops()
    out, _ = torch.ops.wgse_mmseg.triton_band_networks(
        coeffs.contiguous(), list(lengths), params, precision,
        _launch_ints(forward_config) + _launch_ints(backward_config),
        output_grad_is_scratch)
    return out
