"""The check a device kernel passes before its first use in a process.

A kernel compiled for the device at hand (the Triton kernel on a GPU) has
never run there before a user's first training step, and a compiled kernel
can differ from what the interpreter the tests use computes. So the first
time a backend whose :attr:`~.band_network_backends.BandNetworkBackend.
first_use_check` is set would run a *variant* (device, precision of the call,
network shape, band lengths, and the passes the call runs: :data:`PASSES`),
:func:`check_on_first_use` runs it on a small problem of that variant and
compares what the call computes (the output, and with the backward pass
every parameter's gradient and the coefficients' where the call takes it)
with the ``torch`` backend in float64 on the same device, within
:data:`TOLERANCE` at every precision. A compile
or launch error, a NaN or Inf, or an error above the tolerance fails the
check. A log line says the check starts (in a machine's first process it
compiles the kernel, for about a minute on an H100), and the result is kept for
the process and logged once: where it failed, ``'auto'`` then runs the
``torch`` backend; a backend named explicitly raises
:class:`FirstUseCheckFailed` with the same message.

The problem lies on grids (:data:`GRIDS`) chosen so that, for the paper's
network (the one the Triton kernel runs), every operand of the ``H x H``
products is exact in bf16, fp16 and TF32, every product and sum the kernel
forms is exact in float32 (or nearly: sums over many pixels), and every
pre-activation is an odd multiple of half its grid's step, so that no ReLU
decision depends on rounding. A kernel that computes what it should then
agrees with float64 to float32's accumulation at any precision, and one
tolerance tells it from a wrong one. On random data, TF32 or bf16 rounding
moves a few pre-activations across zero, and the gradients behind them by
up to a fifth of their largest magnitude, in any implementation (cuDNN's
too): the first GPU run's random problem failed the kernel at TF32 that
way (0.18; docs/wgse_speed.md, "The first-use check").

Cost (once per variant and process): the problem is the call's band
lengths at :attr:`~.band_network_backends.BandNetworkBackend.check_pixels`
pixels (259 for Triton: two tiles of its largest launch entry, 128
pixels, and a partial third); every launch entry the call's passes may use
is run (Triton: the forward entry alone for inference, with the backward's
32-pixel entry for training, with its 16-pixel entry where the coefficients'
gradient is taken; one launch of each kernel each time, all bands at
once), plus one float64 forward+backward of the ``torch`` backend. Its
arithmetic is negligible on a GPU (259 pixels against the 524288 of a
4x129x256x512 batch); the time is the compiles of the kernels the call
runs, which its first step would pay anyway (docs/wgse_speed.md has the
compile times measured).
"""
import copy
import logging
import time
from typing import Dict, List, NamedTuple, Optional, Sequence

import torch
from torch import Tensor, nn

from ...errors import WgseError, cut

__all__ = ['FirstUseCheckFailed']

#: where a failed check asks to be reported
REPORT_TO = ("the project's bug tracker with this line and the docs/gpu.md "
             'and gpu.json that `bash dev/gpu_report.sh` writes on this '
             'machine')


class FirstUseCheckFailed(WgseError, RuntimeError):
    """A backend named explicitly failed its first-use check."""


class CheckResult(NamedTuple):
    """The outcome of one first-use check."""
    backend: str
    device: str
    variant: str  # precision, network shape, band lengths, readable
    passed: bool
    max_error: Optional[float]  # largest relative error (None: no result)
    tolerance: float
    failure: Optional[str]  # what failed (None when it passed)
    seconds: float

    def message(self) -> str:
        """One log line saying what was checked and how it went."""
        where = _kernel_text(self.backend, self.device, self.variant)
        error = ('-' if self.max_error is None else
                 f'{self.max_error:.2e}')
        if self.passed:
            return (f'WGSE: {where} passed its first-use check against the '
                    f"'torch' backend in float64: largest relative error "
                    f'{error} (tolerance {self.tolerance:.0e}), '
                    f'{self.seconds:.2f} s')
        return (f'WGSE: {where} FAILED its first-use check against the '
                f"'torch' backend in float64: {self.failure}; largest "
                f'relative error {error} (tolerance {self.tolerance:.0e}). '
                f"backend='auto' runs the 'torch' backend instead in this "
                f'process. Please report it at {REPORT_TO}')


#: (backend, device, variant) -> its check in this process
_RESULTS: Dict[tuple, CheckResult] = {}


def _kernel_text(backend: str, device: str, variant: str) -> str:
    """What the log lines call the kernel a check is about."""
    return f'the {backend!r} band-network kernel on {device} ({variant})'


def relative_errors(got: Sequence[Tensor], want: Sequence[Tensor]
                    ) -> List[float]:
    """Per tensor, ``max |got - want|`` over the largest ``|want|`` of that
    tensor (at least a hundredth of the largest of all, so a gradient that
    is nearly zero everywhere is not held to relative precision); ``inf``
    where ``got`` is not finite."""
    largest = max((w.abs().max().item() for w in want if w.numel()),
                  default=0.0) or 1.0
    errors = []
    for g, w in zip(got, want):
        if not torch.isfinite(g).all():
            errors.append(float('inf'))
        elif w.numel():
            errors.append((g.double() - w.double()).abs().max().item() / max(
                w.abs().max().item(), 1e-2 * largest))
        else:
            errors.append(0.0)
    return errors


#: What a call runs, so what its check runs (:func:`passes_of`): the forward
#: pass alone (no gradient: inference), the backward pass too for the
#: parameters' gradients (training: the coefficients come from the data and
#: need none), or the coefficients' gradient as well.
PASSES = ('forward', 'forward and backward',
          "forward and backward with the coefficients' gradient")


def passes_of(networks: Sequence[nn.Module], coeffs: Tensor) -> str:
    """Which of :data:`PASSES` a call on ``coeffs`` made now runs."""
    if torch.is_grad_enabled() and coeffs.requires_grad:
        return PASSES[2]
    if torch.is_grad_enabled() and any(
            p.requires_grad for net in networks for p in net.parameters()):
        return PASSES[1]
    return PASSES[0]


def _variant(backend, networks: Sequence[nn.Module], coeffs: Tensor,
             lengths: Sequence[int], passes: str) -> str:
    net = networks[0]
    return (f'precision {backend.precision(coeffs)}, dim={net.dim} '
            f'kernel_size={net.kernel_size} hidden_channels='
            f'{net.hidden_channels} num_blocks={net.num_blocks}, bands '
            f'{list(lengths)}, {passes}')


#: Largest error of the check against float64, relative to each tensor's
#: largest magnitude (:func:`relative_errors`), at every precision: on the
#: check's problem a right kernel is float32-accurate (about 1e-7).
TOLERANCE = 1e-4


class Grid(NamedTuple):
    """Values ``k * step`` for integers ``|k| <= bound``."""
    step: float
    bound: int


#: The grids of the check's problem: the coefficients and the weights of
#: the loss ``sum(out * weights)``, and per convolution of
#: :meth:`~.band_network.BandNetwork.layers` (first, hidden,
#: last; a deeper network's middle ones take the hidden grids) its weights
#: and its biases, which are odd multiples of half ``step`` within ``bound``
#: steps. Each layer's products with its input are multiples of the bias
#: step (1/2 * 1/4, 1/16 * 1/8, 1/256 * 1/8), so every pre-activation is an
#: odd multiple of half of it, never zero; the hidden activations (multiples
#: of 1/16 up to 4) and the gradients at the hidden layer (multiples of
#: 1/16 up to 1.5) need at most 7 significant bits, which bf16 has.
GRIDS = dict(coefficients=Grid(1 / 2, 2), loss_weights=Grid(1 / 2, 2),
             weights=(Grid(1 / 4, 4), Grid(1 / 8, 4), Grid(1 / 8, 4)),
             biases=(Grid(1 / 8, 8), Grid(1 / 128, 64), Grid(1 / 2048, 128)))


def _on_grid(shape, grid: Grid, generator: torch.Generator,
             odd_halves: bool = False) -> Tensor:
    """float64 values of ``grid`` (``odd_halves``: odd multiples of half
    its step, ``|k + 1/2| <= bound``)."""
    if odd_halves:
        k = torch.randint(-grid.bound, grid.bound, shape,
                          generator=generator, dtype=torch.float64) + 0.5
    else:
        k = torch.randint(-grid.bound, grid.bound + 1, shape,
                          generator=generator, dtype=torch.float64)
    return k * grid.step


def _problem(networks: Sequence[nn.Module], lengths: Sequence[int],
             pixels: int, device: torch.device):
    """Networks like ``networks`` on :data:`GRIDS`, coefficients
    ``(1, C, pixels)`` and the loss's weights, float64 (seeded: the same
    everywhere)."""
    generator = torch.Generator().manual_seed(0)
    # every gradient is checked, the parameters' of a frozen model too
    nets = [copy.deepcopy(net).requires_grad_(True) for net in networks]
    with torch.no_grad():
        for net in nets:
            convs = [conv for conv, _ in net.layers()]
            for index, conv in enumerate(convs):
                which = 0 if index == 0 else 2 if index == len(convs) - 1 \
                    else 1
                conv.weight.copy_(_on_grid(conv.weight.shape,
                                           GRIDS['weights'][which],
                                           generator))
                conv.bias.copy_(_on_grid(conv.bias.shape,
                                         GRIDS['biases'][which], generator,
                                         odd_halves=True))
    shape = (1, sum(lengths), pixels)
    coeffs = _on_grid(shape, GRIDS['coefficients'], generator)
    weights = _on_grid(shape, GRIDS['loss_weights'], generator)
    return ([net.to(device, torch.float64) for net in nets],
            coeffs.to(device), weights.to(device))


def _output_and_grads(backend, networks, coeffs: Tensor, weights: Tensor,
                      lengths, input_grad: Optional[bool], launch: dict
                      ) -> List[Tensor]:
    """The output, the coefficients' gradient (if ``input_grad``) and every
    parameter's of ``sum(out * weights)``; the output alone, without
    gradients, where ``input_grad`` is ``None``."""
    if input_grad is None:
        with torch.no_grad():
            return [backend.run(networks, coeffs, lengths,
                                (1, coeffs.shape[2]), **launch)]
    coeffs = coeffs.detach().requires_grad_(input_grad)
    params = [p for net in networks for p in net.parameters()]
    out = backend.run(networks, coeffs, lengths, (1, coeffs.shape[2]),
                      **launch)
    grads = torch.autograd.grad((out * weights).sum(),
                                ([coeffs] if input_grad else []) + params)
    return [out.detach()] + list(grads)


def _run_check(backend, reference, networks: Sequence[nn.Module],
               coeffs: Tensor, lengths: Sequence[int], passes: str
               ) -> Dict[str, object]:
    """``passed``, ``max_error`` and ``failure`` of one check of the
    launches of a call that runs ``passes`` (:data:`PASSES`)."""
    nets64, coeffs64, weights64 = _problem(networks, lengths,
                                           backend.check_pixels,
                                           coeffs.device)
    with torch.autocast(coeffs.device.type, enabled=False):
        want = _output_and_grads(reference, nets64, coeffs64, weights64,
                                 lengths, True, {})
    nets32 = [copy.deepcopy(net).float() for net in nets64]
    worst = 0.0
    for launch, input_grad in backend.check_launches(
            passes, backend.precision(coeffs)):
        setting = ', '.join([f'{k}={v}' for k, v in launch.items()] + [
            'no gradient' if input_grad is None else
            f'input gradient {input_grad}'])
        try:
            got = _output_and_grads(backend, nets32, coeffs64.float(),
                                    weights64.float(), lengths,
                                    input_grad, launch)
        except Exception as error:  # noqa: BLE001 - the finding
            return dict(passed=False, max_error=None, failure=(
                f'it raised ({setting}): {type(error).__name__}: '
                f'{cut(str(error).strip(), 500)}'))
        names = ['output'] + (['coefficient gradient'] if input_grad
                              else []) + [
            f'gradient of band {band} {name}'
            for band, net in enumerate(nets32)
            for name, _ in net.named_parameters()]
        compared = want[:1] if input_grad is None else want if input_grad \
            else want[:1] + want[2:]
        errors = relative_errors(got, compared)
        index = max(range(len(errors)), key=errors.__getitem__)
        worst = max(worst, errors[index])
        if not errors[index] <= TOLERANCE:
            what = ('NaN or Inf' if errors[index] == float('inf')
                    else 'disagrees')
            return dict(passed=False, max_error=errors[index],
                        failure=f'{names[index]} {what} ({setting})')
    return dict(passed=True, max_error=worst, failure=None)


def check_on_first_use(backend, reference, networks: Sequence[nn.Module],
                       coeffs: Tensor, lengths: Sequence[int]
                       ) -> CheckResult:
    """The first-use check of ``backend`` for the variant of this call
    (``coeffs`` ``(B, C, P)``, bands of ``lengths``), against ``reference``
    (the ``torch`` backend) in float64; run once per process and variant,
    logged when it starts (info) and once with its result (passed: info;
    failed: warning)."""
    device = str(coeffs.device)
    passes = passes_of(networks, coeffs)
    key = (backend.name, device, _variant(backend, networks, coeffs,
                                          lengths, passes))
    if key not in _RESULTS:
        _log(logging.INFO,
             f'WGSE: checking {_kernel_text(*key)} against the \'torch\' '
             f'backend in float64 before its first use; a machine\'s first '
             f'process compiles the kernel first (about a minute on an H100)')
        start = time.perf_counter()
        with torch.inference_mode(False), torch.enable_grad():
            outcome = _run_check(backend, reference, networks, coeffs,
                                 lengths, passes)
        result = _RESULTS[key] = CheckResult(
            backend.name, device, key[2],
            tolerance=TOLERANCE,
            seconds=time.perf_counter() - start, **outcome)
        _log(logging.INFO if result.passed else logging.WARNING,
             result.message())
    return _RESULTS[key]


def _log(level: int, message: str) -> None:
    """Into the training log (mmengine's current logger) where mmengine
    imports, else Python's logging."""
    try:
        from mmengine.logging import print_log
    except ImportError:
        logging.getLogger(__name__).log(level, message)
    else:
        print_log(message, logger='current', level=level)
