"""The backends that run WGSE's band networks, behind one interface.

A backend takes the band networks
(:class:`~wgse_mmseg.core.wgse.band_network.BandNetwork`, one per wavelet band)
and every pixel's wavelet coefficients ``(B, C, P)`` (``P = H*W`` pixels; the
bands one after another along ``C``) and returns the networks' outputs, ``(B,
C, P)`` too. Each backend declares the memory layout it reads without a copy
(:meth:`BandNetworkBackend.pixel_major`, :func:`pixel_major`): band-major,
``(B, C, P)`` contiguous, one coefficient of every pixel a contiguous row (the
Triton kernel's), or pixel-major, the ``(B, C, P)`` view of ``(B, P, C)`` rows,
one pixel's coefficients a row (the CPU kernels'); WGSE computes the
coefficients in it, and a pixel-major backend returns its output pixel-major,
so that nothing is copied between the layouts and the gradient of the output
reaches the kernel in its own layout. Given the other layout, a backend copies.
All compute the same function; they differ in where they run and how fast:

* ``'torch'``: torch operations, on any device (CPU, CUDA, MPS) and dtype,
  every variant. ``dim=1`` runs the chunked kernel of
  :mod:`~wgse_mmseg.core.wgse.torch_band_networks` on the CPU and the
  ``nn.Conv1d`` modules (the device's library convolutions) in chunks of
  :data:`DEVICE_CHUNK_BYTES` elsewhere; ``dim`` 2 and 3 run the
  ``nn.Conv3d`` modules one band and sample at a time.
* ``'compiled'``: the C kernel of
  :mod:`~wgse_mmseg.core.wgse.compiled_band_networks`: CPU with AVX2/FMA,
  where the extension was built; float32, the paper's width and kernel.
* ``'triton'``: the kernel of
  :mod:`~wgse_mmseg.core.wgse.triton_band_networks`: CUDA, where triton
  imports; the paper's network shape.
* ``'reference'``: the band networks' own ``nn.Conv`` modules, the
  definition the others are tested against: any variant, device and dtype,
  following autocast; it keeps every activation for the backward pass
  (``dim=1``: ``B*H*W`` signals at once), so it is for tests and small
  inputs, and ``'auto'`` never picks it.

``'auto'`` picks ``triton`` for CUDA tensors and ``compiled`` for CPU
tensors where they can run the call, and ``torch`` otherwise (and while
``torch.jit`` traces, so that FLOP counters see the convolutions). A
backend compiled for the device (``triton``) is checked against ``torch``
before its first use there (:mod:`.first_use_check`); where the check
fails, ``'auto'`` runs ``torch`` and logs why. Naming a backend that cannot
run a call, or that fails the check, is an error that says why; nothing
falls back silently then.

Second-order gradients (a backward pass with ``create_graph=True``, as a
gradient penalty takes): ``torch``, ``compiled`` and ``reference`` give
them (the CPU kernels then differentiate torch's convolutions,
:func:`~wgse_mmseg.core.wgse.torch_band_networks.differentiable_backward`);
``triton`` refuses them with an error naming ``'torch'``, never a wrong
gradient (:class:`_FirstOrderOnly`).

Every backend but ``'reference'`` keeps training memory ``O(B*T*H*W)``:
hidden activations are recomputed in the backward pass, chunk by chunk
(``torch``, ``compiled``) or tile by tile (``triton``), never kept for all
pixels at once.
"""
from typing import Dict, List, Optional, Sequence, Tuple

import torch
from torch import Tensor, nn
from torch.utils.checkpoint import checkpoint

from . import (compiled_band_networks, triton_band_networks,
               triton_launch_choices)
from .first_use_check import (PASSES, CheckResult, FirstUseCheckFailed,
                              check_on_first_use, passes_of)
from .torch_band_networks import torch_band_networks
from ...argument_checks import ArgumentError

__all__ = []

Weights = List[List[Tuple[Tensor, Tensor]]]


def _weights(networks: Sequence[nn.Module]
             ) -> Tuple[Weights, List[Optional[int]]]:
    """Per band, per convolution ``(weight, bias)``; the residual plan."""
    plans = [net.layers() for net in networks]
    weights = [[(conv.weight, conv.bias) for conv, _ in plan]
               for plan in plans]
    return weights, [residual for _, residual in plans[0]]


def _input_grad(passes: str) -> Optional[bool]:
    """Whether a call that runs ``passes`` (:data:`.first_use_check.PASSES`)
    computes the coefficients' gradient; ``None``: no gradient at all."""
    forward, backward, input_grad = PASSES
    return {forward: None, backward: False, input_grad: True}[passes]


class BandNetworkBackend:
    """One way to run the band networks. Subclasses set :attr:`name` and
    override :meth:`run` and the checks that apply to them."""

    #: the name a config gives (``WGSE(backend=...)``)
    name = ''

    def unavailable(self) -> Optional[str]:
        """Why this installation cannot run the backend at all, or
        ``None``."""
        return None

    def unsupported(self, networks: Sequence[nn.Module]) -> Optional[str]:
        """Why it cannot run these networks (whatever the input), or
        ``None``."""
        return None

    def unsupported_call(self, networks: Sequence[nn.Module],
                         coeffs: Tensor) -> Optional[str]:
        """Why it cannot run these networks on ``coeffs`` (device, dtype,
        gradients), or ``None``."""
        return None

    def pixel_major(self, networks: Sequence[nn.Module],
                    device_type: str) -> bool:
        """Whether :meth:`run` on ``device_type`` tensors reads pixel-major
        coefficients (the ``(B, C, P)`` view of ``(B, P, C)`` rows) without
        a copy, and returns its output so; else band-major ``(B, C, P)``
        contiguous."""
        return False

    def cannot_run(self, networks: Sequence[nn.Module],
                   coeffs: Optional[Tensor] = None) -> Optional[str]:
        """The first reason of the three checks, or ``None``."""
        return self.unavailable() or self.unsupported(networks) or (
            None if coeffs is None else
            self.unsupported_call(networks, coeffs))

    def run(self, networks: Sequence[nn.Module], coeffs: Tensor,
            lengths: Sequence[int], spatial: Tuple[int, int],
            output_grad_is_scratch: bool = False, **launch) -> Tensor:
        """The band networks on ``coeffs`` ``(B, C, P)``, bands of
        ``lengths`` side by side, pixels of a ``spatial`` ``(H, W)``
        frame; same shape and dtype out. ``output_grad_is_scratch``: the
        gradient that will reach the output in the backward pass is a
        tensor nothing else reads (WGSE's synthesis product makes a new
        one), which a backend may overwrite (the Triton kernel does).
        ``launch``: one of :meth:`check_launches` (the first-use check
        names each)."""
        raise NotImplementedError

    # The first-use check (:mod:`.first_use_check`), for kernels compiled
    # for the device at hand.

    #: whether a variant is checked the first time it runs in a process
    first_use_check = False
    #: pixels of the check's problem
    check_pixels = 67

    def precision(self, coeffs: Tensor) -> str:
        """The arithmetic precision of a call on ``coeffs`` made now."""
        return str(coeffs.dtype).replace('torch.', '')

    def check_launches(self, passes: str, precision: str
                       ) -> Sequence[Tuple[Dict[str, object],
                                           Optional[bool]]]:
        """The launch settings a call that runs ``passes`` (one of
        :data:`~.first_use_check.PASSES`) at ``precision``
        (:meth:`precision`) may use, each with whether the coefficients'
        gradient is computed there (``None``: no gradient, the forward pass
        alone): the check runs each pair."""
        return (({}, _input_grad(passes)), )


class TorchBackend(BandNetworkBackend):
    """torch operations: every variant, dtype and device. ``dim=1`` runs
    in float32 (float64 for float64) whatever autocast says: on the CPU the
    fused kernel of :mod:`.torch_band_networks`; elsewhere (CUDA: what GPU
    users get with ``'torch'`` or when ``'auto'``'s check fails) the
    ``nn.Conv1d`` modules, i.e. the device library's convolutions (cuDNN),
    on chunks of pixels sized by :data:`DEVICE_CHUNK_BYTES`, each chunk
    recomputed in the backward pass."""

    name = 'torch'

    def pixel_major(self, networks, device_type):
        # the CPU kernel; nn.Conv modules elsewhere and under tracing
        return (networks[0].dim == 1 and device_type == 'cpu' and
                not torch.jit.is_tracing())

    def run(self, networks, coeffs, lengths, spatial,
            output_grad_is_scratch=False):
        if networks[0].dim == 1 and not torch.jit.is_tracing():
            with torch.autocast(coeffs.device.type, enabled=False):
                if coeffs.device.type != 'cpu':
                    return _module_bands(networks, coeffs, lengths, spatial,
                                         recompute=True)
                weights, residuals = _weights(networks)
                out = torch_band_networks(_pixel_rows(coeffs), lengths,
                                          weights, residuals)
            return _as_coefficients(out, coeffs.shape)
        # nn.Conv modules: dim 2 and 3, and under tracing (FLOP counters,
        # jit.trace see the convolutions). They follow autocast.
        return _module_bands(networks, coeffs, lengths, spatial,
                             recompute=True)


class ReferenceBackend(BandNetworkBackend):
    """The ``nn.Conv`` modules as they are, every activation kept: what
    tests compare the kernels with."""

    name = 'reference'

    def run(self, networks, coeffs, lengths, spatial,
            output_grad_is_scratch=False):
        return _module_bands(networks, coeffs, lengths, spatial,
                             recompute=False)


#: Bytes that one chunk's activations and their gradients may take when
#: ``dim=1`` band networks run as ``nn.Conv1d`` modules chunk by chunk
#: (:func:`_module_bands`, the ``'torch'`` backend off the CPU): what bounds
#: the backend's memory beyond its ``O(B*T*H*W)`` inputs and outputs.
DEVICE_CHUNK_BYTES = 1 << 29


def _pixels_per_chunk(network: nn.Module, length: int, itemsize: int,
                      budget: int = DEVICE_CHUNK_BYTES) -> int:
    """How many pixels of a band of ``length`` coefficients fit ``budget``
    bytes of activations (``itemsize`` bytes each) in a recomputed
    forward+backward of a ``dim=1`` band network: every convolution's
    output is kept for the backward pass (``sum`` of the output widths per
    coefficient), and at most three more of the widest exist at once
    (a convolution's output and its ReLU; two gradients)."""
    widths = [conv.out_channels for conv, _ in network.layers()]
    per_pixel = (sum(widths) + 3 * max(widths)) * length * itemsize
    return max(1, budget // per_pixel)


def _module_bands(networks: Sequence[nn.Module], coeffs: Tensor,
                  lengths: Sequence[int], spatial: Tuple[int, int],
                  recompute: bool,
                  chunk_bytes: int = DEVICE_CHUNK_BYTES) -> Tensor:
    """The networks as ``nn.Conv`` modules on ``(B, C, P)`` coefficients.

    ``dim=1`` runs every pixel as a ``(1, L)`` signal; ``dim`` 2 and 3 run
    one sample's band as a ``(1, 1, L, H, W)`` volume.

    With ``recompute``, only a part of the activations exists at once:
    ``dim=1`` runs :func:`_pixels_per_chunk` pixels at a time (within
    ``chunk_bytes``), ``dim`` 2 and 3 one sample at a time; when gradients
    are wanted, each part's activations are recomputed in the backward
    pass (``torch.utils.checkpoint``). Without, every activation of every
    pixel is kept (the ``'reference'`` backend).
    """
    batch, _, pixels = coeffs.shape
    train = recompute and passes_of(networks, coeffs) != PASSES[0]
    outs = []
    for network, band in zip(networks, coeffs.split(list(lengths), dim=1)):
        length = band.shape[1]
        if network.dim == 1:
            signals = band.transpose(1, 2).reshape(batch * pixels, 1, length)
            step = _pixels_per_chunk(network, length, coeffs.element_size(),
                                     chunk_bytes) if recompute else None
            if step is None or (signals.shape[0] <= step and not train):
                out = network(signals)
            else:
                out = torch.cat([
                    checkpoint(network, chunk, use_reentrant=False)
                    if train else network(chunk)
                    for chunk in signals.split(step)])
            outs.append(out.reshape(batch, pixels, length).transpose(1, 2)
                        .to(coeffs.dtype))
            continue
        samples = []
        for sample in band.reshape(batch, 1, length, *spatial).split(1):
            samples.append(checkpoint(network, sample, use_reentrant=False)
                           if train else network(sample))
        out = torch.cat(samples) if samples else band.new_empty(
            0, 1, length, *spatial)
        outs.append(out.reshape(batch, length, pixels).to(coeffs.dtype))
    return torch.cat(outs, dim=1)


def _pixel_rows(coeffs: Tensor) -> Tensor:
    """``(B, C, P)`` coefficients as ``(B*P, C)`` rows, one pixel a row:
    the CPU kernels' layout; a view of pixel-major coefficients, a copy of
    others."""
    return coeffs.transpose(1, 2).reshape(-1, coeffs.shape[1])


def _as_coefficients(rows: Tensor, shape: torch.Size) -> Tensor:
    """:func:`_pixel_rows`' ``(B*P, C)`` as ``shape`` ``(B, C, P)``: the
    pixel-major view, nothing copied."""
    batch, columns, pixels = shape
    return rows.view(batch, pixels, columns).transpose(1, 2)


class CompiledBackend(BandNetworkBackend):
    """The compiled C kernel: CPU, float32, the paper's width and kernel."""

    name = 'compiled'

    def unavailable(self):
        return compiled_band_networks.unavailable()

    def unsupported(self, networks):
        if networks[0].dim != 1:
            return f'it runs dim=1 band networks, not dim={networks[0].dim}'
        return None

    def unsupported_call(self, networks, coeffs):
        weights, residuals = _weights(networks)
        return compiled_band_networks.unsupported(_pixel_rows(coeffs),
                                                  weights, residuals)

    def pixel_major(self, networks, device_type):
        return True

    def run(self, networks, coeffs, lengths, spatial,
            output_grad_is_scratch=False):
        weights, residuals = _weights(networks)
        with torch.autocast(coeffs.device.type, enabled=False):
            out = compiled_band_networks.compiled_band_networks(
                _pixel_rows(coeffs), lengths, weights, residuals)
        return _as_coefficients(out, coeffs.shape)


class TritonBackend(BandNetworkBackend):
    """The Triton kernel: CUDA, float32 in and out, the paper's network
    shape; its products follow autocast and torch's TF32 flag."""

    name = 'triton'

    def unavailable(self):
        return triton_band_networks.unavailable()

    def unsupported(self, networks):
        net = networks[0]
        return triton_band_networks.unsupported_network(
            net.dim, net.kernel_size, net.hidden_channels, net.num_blocks)

    def unsupported_call(self, networks, coeffs):
        return triton_band_networks.unsupported_tensor(coeffs)

    def run(self, networks, coeffs, lengths, spatial,
            output_grad_is_scratch=False, **launch):
        weights, _ = _weights(networks)
        precision = self.precision(coeffs)
        with torch.autocast(coeffs.device.type, enabled=False):
            out = triton_band_networks.triton_band_networks(
                coeffs, lengths, weights, precision,
                output_grad_is_scratch=output_grad_is_scratch, **launch)
        return _FirstOrderOnly.apply(out, self.name)

    @property
    def first_use_check(self):
        # compiled for a GPU; the interpreter runs what the tests checked
        return not triton_band_networks.interpreting()

    #: two tiles of the largest launch entry and a partial third
    check_pixels = 2 * max(config.block for config in (
        triton_launch_choices.FORWARD_CONFIGS +
        triton_launch_choices.backward_configs())) + 3

    def precision(self, coeffs):
        return triton_launch_choices.dot_precision(coeffs.device.type)

    def check_launches(self, passes, precision):
        # every entry the call's passes may launch, each at least once: the
        # forward entries, and the backward entries chosen for its input
        # gradient and precision (no compile of a kernel the call does not
        # run)
        forward = triton_launch_choices.FORWARD_CONFIGS
        input_grad = _input_grad(passes)
        if input_grad is None:
            return [(dict(forward_config=config), None)
                    for config in forward]
        backward = triton_launch_choices.backward_configs(input_grad,
                                                          precision)
        return [(dict(forward_config=forward[min(i, len(forward) - 1)],
                      backward_config=backward[min(i, len(backward) - 1)]),
                 input_grad)
                for i in range(max(len(forward), len(backward)))]


class _FirstOrderOnly(torch.autograd.Function):
    """The identity on a kernel's output whose backward pass cannot be
    differentiated: a backward with ``create_graph=True`` through it is an
    error naming the backend, before the kernel's backward runs."""

    @staticmethod
    def forward(ctx, out: Tensor, backend: str) -> Tensor:
        ctx.backend = backend
        return out.view_as(out)

    @staticmethod
    def backward(ctx, grad: Tensor):
        if torch.is_grad_enabled():
            raise RuntimeError(
                f'WGSE backend={ctx.backend!r} gives no second-order '
                f'gradients (a backward pass with create_graph=True, as a '
                f'gradient penalty takes); use backend=\'torch\', which '
                f'does')
        return grad, None


#: name -> backend
BACKENDS = {backend.name: backend for backend in (
    TorchBackend(), CompiledBackend(), TritonBackend(), ReferenceBackend())}
#: what ``WGSE(backend=...)`` accepts
CHOICES = ('auto', ) + tuple(BACKENDS)
#: ``'auto'``'s first choice per device type; ``torch`` where it cannot run
_AUTO = {'cuda': 'triton', 'cpu': 'compiled'}


def _choices() -> str:
    lines = []
    for name, backend in BACKENDS.items():
        reason = backend.unavailable()
        lines.append(f'{name!r}' + (f' (unavailable: {reason})'
                                    if reason else ''))
    return "'auto', " + ', '.join(lines)


def get_backend(entry: str, name: str, networks: Sequence[nn.Module]
                ) -> Optional[BandNetworkBackend]:
    """Check ``entry``'s configured backend name against the networks
    before any input is seen.

    Returns:
        The backend, or ``None`` for ``'auto'``.

    Raises:
        ArgumentError: an unknown name, or a backend that this installation
            or these networks rule out, with the reason and the choices.
    """
    if name == 'auto':
        return None
    if not isinstance(name, str) or name not in BACKENDS:
        raise ArgumentError(entry, 'backend', f'one of {_choices()}', name)
    reason = BACKENDS[name].cannot_run(networks)
    if reason:
        raise ArgumentError(
            entry, 'backend', f'a backend that can run these band networks '
            f'({name!r}: {reason}); choices: {_choices()}', name)
    return BACKENDS[name]


def pixel_major(name: str, networks: Sequence[nn.Module],
                device_type: str) -> bool:
    """Whether coefficients on ``device_type`` for the configured backend
    ``name`` are best made pixel-major
    (:meth:`BandNetworkBackend.pixel_major`): for ``'auto'``, where both
    backends it may pick there (its first choice and ``'torch'``) read
    them so."""
    if name != 'auto':
        return BACKENDS[name].pixel_major(networks, device_type)
    preferred = BACKENDS.get(_AUTO.get(device_type, 'torch'))
    return all(backend.pixel_major(networks, device_type)
               for backend in (preferred, BACKENDS['torch']))


def resolve_backend(name: str, networks: Sequence[nn.Module],
                    coeffs: Tensor, lengths: Sequence[int]
                    ) -> Tuple[BandNetworkBackend, Optional[CheckResult]]:
    """The backend that runs ``networks`` on ``coeffs`` ``(B, C, P)`` (bands
    of ``lengths``) for the configured ``name`` (``'auto'`` or one of
    :data:`BACKENDS`, checked by :func:`get_backend` where it was set), and
    the first-use check behind the choice: the one the backend passed, the one
    ``'auto'`` fell back from to ``'torch'``, or ``None`` where no check
    applies (:mod:`.first_use_check`).

    Raises:
        ValueError: a named backend cannot run this call (say, ``'triton'``
            on a CPU tensor); the message says why and lists the choices.
        FirstUseCheckFailed: a named backend failed its first-use check
            here; the message says what failed and how to report it.
    """
    backend = None if name == 'auto' else BACKENDS[name]
    if backend is None:
        if torch.jit.is_tracing():  # FLOP counters, jit.trace: see convs
            return BACKENDS['torch'], None
        preferred = BACKENDS.get(_AUTO.get(coeffs.device.type, 'torch'))
        if preferred.cannot_run(networks, coeffs) is not None:
            return BACKENDS['torch'], None
        check = _first_use_check(preferred, networks, coeffs, lengths)
        if check is None or check.passed:
            return preferred, check
        return BACKENDS['torch'], check
    reason = backend.unsupported_call(networks, coeffs)
    if reason:
        raise ValueError(
            f'backend={name!r} cannot run on {coeffs.dtype} coefficients on '
            f'{coeffs.device}: {reason}. Choices: {_choices()}')
    check = _first_use_check(backend, networks, coeffs, lengths)
    if check is not None and not check.passed:
        raise FirstUseCheckFailed(
            f'backend={name!r} was named, so nothing falls back: '
            f'{check.message()}')
    return backend, check


def _first_use_check(backend: BandNetworkBackend,
                     networks: Sequence[nn.Module], coeffs: Tensor,
                     lengths: Sequence[int]) -> Optional[CheckResult]:
    if not backend.first_use_check:
        return None
    return check_on_first_use(backend, BACKENDS['torch'], networks, coeffs,
                              lengths)
