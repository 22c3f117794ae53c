"""WGSE: wavelet-guided spike enhancing (Zhang et al., AAAI 2023).

A spike stream ``(B, T, H, W)`` is decomposed per pixel along time by a
multi-level 1-D DWT into ``level + 1`` bands; each band passes through its own
small residual CNN; the inverse DWT maps the result back to exactly ``T``
channels, so any network with ``in_channels=T`` can follow.

Variants (all one class; MMSeg's registry name is ``WGSE``):

* ``dim=1``: temporal convolutions per pixel (the paper's default);
* ``dim=2``: spatial ``k x k`` convolutions on each coefficient plane;
* ``dim=3``: spatio-temporal ``k x k x k`` convolutions;
* ``num_blocks=2``: the "long" variant (residual layers and output
  convolutions doubled);
* ``wavelet=None``: the "TRCNN without wavelets" ablation, one band network
  on the raw stream.

Options of the training recipe (``docs/wgse_vs_tfp.md`` ablates them):
``init='lowpass'`` starts the module at the level-``level`` approximation of
the stream, a long window average like TFP's, instead of at random;
``output_norm=True`` standardises the output.
"""
import functools
from typing import List, Optional, Tuple

import pywt
import torch
import torch.nn as nn

from ...argument_checks import (ArgumentError, check_choice, check_flag,
                                check_integer, check_parameter_count)
from ..checks import check_finite, check_finite_parameters
from ..wavelets import (SUPPORTED_MODES, analysis_matrix, band_lengths,
                        synthesis_matrix)
from .band_network import BandNetwork
from .band_network_backends import get_backend, pixel_major, resolve_backend
from .first_use_check import CheckResult
from .recomputation import saved_as_recomputation

__all__ = ['WGSE']


def _product(matrix: torch.Tensor, x: torch.Tensor,
             pixel_major: bool) -> torch.Tensor:
    """``matrix @ x`` ``(B, M, P)`` for ``matrix`` ``(M, K)`` and ``x``
    ``(B, K, P)`` of any strides; with ``pixel_major``, computed as the
    transposed product, so that its memory is ``(B, P, M)`` rows and the
    gradient that reaches ``x`` in the backward pass is ``(B, P, K)`` rows:
    the CPU kernels' layout on both sides, no copy between layouts
    (:mod:`.band_network_backends`)."""
    if pixel_major:
        return torch.matmul(x.mT, matrix.mT).mT
    return torch.matmul(matrix, x)


@functools.lru_cache(maxsize=32)
def _cached_transform(num_steps: int, wavelet: str, level: int,
                      mode: str, device: torch.device, dtype: torch.dtype
                      ) -> Tuple[torch.Tensor, torch.Tensor, List[int]]:
    """The DWT's analysis ``(C, T)`` and synthesis ``(T, C)`` matrices and
    the band lengths, for ``T = num_steps``: constants of the arguments,
    made once (PyWavelets, NumPy)."""
    analysis = analysis_matrix(num_steps, wavelet, level, mode)
    lengths = list(band_lengths(num_steps, wavelet, level, mode))
    synthesis = synthesis_matrix(lengths, wavelet, mode, length=num_steps)
    return (torch.tensor(analysis, dtype=dtype, device=device),
            torch.tensor(synthesis, dtype=dtype, device=device), lengths)


def _transform(num_steps: int, wavelet: str, level: int, mode: str,
               device: torch.device, dtype: torch.dtype
               ) -> Tuple[torch.Tensor, torch.Tensor, List[int]]:
    """:func:`_cached_transform`, which ``torch.compile`` calls as it is
    and whose result it takes as a constant of the graph, instead of
    tracing NumPy (which would break the graph) or the cache."""
    return _cached_transform(num_steps, wavelet, level, mode, device, dtype)


# What ``torch.compiler.assume_constant_result(_transform)`` sets, without
# importing torch._dynamo (seconds) with the module; a test holds the two
# equal.
_transform._dynamo_marked_constant = True

#: ``WGSE(init=...)``: ``'default'`` (PyTorch's initialisation of every
#: convolution) or ``'lowpass'`` (see :meth:`WGSE.init_lowpass`)
INITS = ('default', 'lowpass')


#: the constant a detail band's network outputs after ``init='lowpass'``:
#: small, and far enough above zero that its final ReLU passes gradients
#: and Adam's first steps (about the learning rate each) do not push it
#: below zero, where the band would stay dead (at 1e-3, two of the five
#: detail bands died within 30 steps of lr 1e-3 in a trial)
LOWPASS_DETAIL_BIAS = 0.02


def _activation_bound(networks: nn.ModuleList,
                      input_bound: torch.Tensor) -> torch.Tensor:
    """An upper bound (a scalar tensor) on every activation of the
    ``networks`` (alike: :class:`BandNetwork` of the same arguments) given
    inputs of magnitude at most ``input_bound``: each convolution's output
    is at most its largest absolute row sum of weights times its input's
    bound plus its largest absolute bias, plus the bound of the activation
    a residual adds (ReLU only lowers magnitudes). Not finite where a
    weight is not; loose, but a network of sane weights stays far inside
    float32's range (about 2e2 for one block and 4e4 for two at PyTorch's
    initialisation and 0/1 spikes). The networks' layers are stacked, a
    few operations a layer whatever the number of bands."""
    plans = [network.layers() for network in networks]
    bounds = [input_bound.detach().float().expand(len(plans))]
    for position, (_, residual) in enumerate(plans[0]):
        convs = [plan[position][0] for plan in plans]
        weights = torch.stack([conv.weight.detach() for conv in convs])
        bound = weights.float().abs().flatten(2).sum(2).amax(1) * bounds[-1]
        biases = [conv.bias.detach() for conv in convs
                  if conv.bias is not None]
        if biases:
            bound = bound + torch.stack(biases).float().abs().amax(1)
        if residual is not None:
            bound = bound + bounds[residual]
        bounds.append(bound)
    return torch.stack(bounds).max()


def _magnitude(tensor: torch.Tensor) -> torch.Tensor:
    """The largest absolute value of ``tensor`` as a float32 scalar tensor
    (0 if empty, NaN if it holds NaN)."""
    tensor = tensor.detach()
    if not tensor.numel():
        return tensor.new_zeros((), dtype=torch.float32)
    if tensor.dtype == torch.bool:
        return tensor.any().float()
    if tensor.is_floating_point():
        return tensor.abs().amax().float()
    return torch.maximum(tensor.amax().float().abs(),
                         tensor.amin().float().abs())


def _largest_weight(module: nn.Module) -> Tuple[str, float]:
    """The name and absolute value of ``module``'s largest parameter
    value."""
    return max(((name, float(parameter.detach().abs().max()))
                for name, parameter in module.named_parameters()
                if parameter.numel()), key=lambda item: item[1])


class WGSE(nn.Module):
    """Wavelet-guided spike enhancing: ``(B, T, H, W) -> (B, T, H, W)``.

    Args:
        dim: 1 (temporal), 2 (spatial) or 3 (spatio-temporal) convolutions
            in the band networks.
        wavelet: a discrete PyWavelets wavelet name, or ``None`` for the
            "TRCNN without wavelets" ablation (one band network on the raw
            stream).
        level: number of DWT levels; ``level + 1`` band networks. Levels
            above ``pywt.dwt_max_level`` are allowed, as in the paper.
        mode: DWT boundary mode, one of PyWavelets' (``'zero'``,
            ``'constant'``, ``'symmetric'``, ``'reflect'``, ``'periodic'``,
            ``'antisymmetric'``, ``'periodization'``).
        kernel_size: odd kernel size of every convolution.
        hidden_channels: width of the band networks.
        num_blocks: residual layers (and output convolutions) per band;
            2 is the paper's "long" variant.
        backend: what runs the band networks: ``'auto'``, ``'torch'``,
            ``'compiled'``, ``'triton'`` or ``'reference'``. ``'auto'``
            picks the Triton kernel for CUDA inputs (once it passed its
            first-use check on the device: ``backend_check``) and the
            compiled kernel for CPU inputs where they can run, else
            ``'torch'``; a named backend that cannot run, or fails that
            check, is an error. Every backend but
            ``'reference'`` (the ``nn.Conv`` modules as they are, for
            tests) recomputes hidden activations in the backward pass.
        init: ``'default'`` or ``'lowpass'`` (:meth:`init_lowpass`).
        output_norm: standardise the output ``(B, T, H, W)`` with one
            batch-norm channel over all its values (batch statistics in
            training, running statistics in evaluation, a learned scale and
            shift), so that the network behind gets zero-mean, unit-variance
            input whatever scale the band networks produce.

    Attributes:
        backend_in_use: the backend that ran the last forward pass
            (``None`` before the first).
        backend_check: the first-use check behind it (its backend,
            device, variant, ``passed``, ``max_error``, ``tolerance``,
            ``failure`` and ``seconds``, and ``message()``, the log line):
            the one the backend passed, or the one ``'auto'`` fell back
            from to ``'torch'``; ``None`` where no check applies (the CPU
            backends, the Triton interpreter) and before the first pass.

    The transform runs in float32 (float64 for a float64 module) even under
    autocast; so do the ``torch`` and ``compiled`` backends' ``dim=1``
    kernels. The Triton kernel rounds the operands of its hidden products
    to autocast's dtype (or TF32, as torch's flags allow), and the
    ``nn.Conv3d`` modules of ``dim`` 2 and 3 follow autocast.
    """

    def __init__(self, dim: int = 1, wavelet: Optional[str] = 'db8',
                 level: int = 5, mode: str = 'zero', kernel_size: int = 3,
                 hidden_channels: int = 32, num_blocks: int = 1,
                 backend: str = 'auto', init: str = 'default',
                 output_norm: bool = False):
        super().__init__()
        check_choice('WGSE', 'dim', dim, (1, 2, 3))
        check_choice('WGSE', 'wavelet', wavelet,
                     pywt.wavelist(kind='discrete'), optional=True,
                     description='a discrete PyWavelets wavelet name '
                     '(pywt.wavelist(kind="discrete"))')
        check_integer('WGSE', 'level', level, 1)
        check_choice('WGSE', 'mode', mode, SUPPORTED_MODES)
        check_integer('WGSE', 'kernel_size', kernel_size, 1, odd=True)
        check_integer('WGSE', 'hidden_channels', hidden_channels, 1)
        check_integer('WGSE', 'num_blocks', num_blocks, 1)
        check_choice('WGSE', 'init', init, INITS)
        check_flag('WGSE', 'output_norm', output_norm)
        num_bands = 1 if wavelet is None else level + 1
        check_parameter_count(
            'WGSE', num_bands * BandNetwork.parameter_count(
                dim, kernel_size, hidden_channels, num_blocks),
            'level, kernel_size, hidden_channels and num_blocks')
        self.dim = dim
        self.wavelet = wavelet
        self.level = level
        self.mode = mode
        self.band_networks = nn.ModuleList([
            BandNetwork(dim, kernel_size, hidden_channels, num_blocks)
            for _ in range(num_bands)
        ])
        self.backend = backend
        self.backend_in_use: Optional[str] = None
        self.backend_check: Optional[CheckResult] = None
        self.output_norm = nn.BatchNorm1d(1) if output_norm else None
        if init == 'lowpass':
            self.init_lowpass()

    @property
    def backend(self) -> str:
        """The configured backend's name (the constructor's ``backend``),
        checked against the band networks where it is set."""
        return self._backend_name

    @backend.setter
    def backend(self, name: str) -> None:
        get_backend('WGSE', name, self.band_networks)
        self._backend_name = name

    def init_lowpass(self) -> None:
        """Start at the stream's low-pass part: the approximation band's
        network passes its (non-negative) coefficients through and every
        detail band's network outputs :data:`LOWPASS_DETAIL_BIAS`, so the
        output is about the inverse DWT of the level-``level``
        approximation alone, a smooth window average of the stream (for
        db8 at 5 levels and T=41, about as long as TFP's window of 21).
        Without wavelets (``wavelet=None``) the one band network passes the
        stream through."""
        for index, network in enumerate(self.band_networks):
            if index == 0:
                network.init_pass_through(gain=1.0)
            else:
                network.init_pass_through(gain=0.0,
                                          bias=LOWPASS_DETAIL_BIAS)

    def _matrices(self, num_steps: int, device: torch.device,
                  dtype: torch.dtype) -> Tuple[torch.Tensor, torch.Tensor,
                                               List[int]]:
        """Analysis ``(C, T)`` and synthesis ``(T, C)`` matrices, band
        sizes."""
        return _transform(num_steps, self.wavelet, self.level, self.mode,
                          device, dtype)

    def _check_range(self, spikes: torch.Tensor,
                     analysis: Optional[torch.Tensor],
                     synthesis: Optional[torch.Tensor]) -> None:
        """Raise ``ValueError`` unless ``spikes`` ``(B, T, H, W)`` are
        finite and every activation of the band networks on their wavelet
        coefficients (``analysis`` ``(C, T)``, ``None`` without wavelets),
        and the output of the ``synthesis`` ``(T, C)``, are bounded inside
        float32's range (:func:`_activation_bound`). NaN or Inf spikes are
        named by :func:`~wgse_mmseg.core.checks.check_finite`, NaN or Inf
        weights by
        :func:`~wgse_mmseg.core.checks.check_finite_parameters`, finite
        ones that could overflow by the largest weight and input. Backends
        differ in what an overflow gives (NaN, or zeros behind a ReLU that
        drops NaN); inside the bound they agree. One pass over the spikes
        (the one a finiteness check makes) and one device sync; under
        ``torch.compile`` only the spikes' check, inside the graph (the
        bound of the weights is eager's); skipped while ``torch.export``
        traces, as ``check_finite`` is."""
        if torch.compiler.is_exporting():
            return
        if torch.compiler.is_compiling():
            # in the graph: the spikes' check (an assertion, no sync); the
            # weights' bound needs a branch on a value, eager only
            check_finite('WGSE', 'spikes', spikes)
            return
        inputs = _magnitude(spikes)
        bound = inputs
        if analysis is not None:
            bound = bound * analysis.detach().abs().sum(1).max().float()
        bound = _activation_bound(self.band_networks, bound)
        if synthesis is not None:
            bound = bound * synthesis.detach().abs().sum(1).max().float()
        limit = torch.finfo(torch.float32).max
        if bool(bound <= limit):
            return
        check_finite('WGSE', 'spikes', spikes)
        check_finite_parameters('WGSE', self)
        name, value = _largest_weight(self)
        raise ValueError(
            f'WGSE: its activations could exceed float32\'s range '
            f'({limit:.3g}): they are bounded only by {float(bound):.3g}, '
            f'from the largest weight, {name} ({value:.3g}), and the '
            f'largest magnitude of the spikes ({float(inputs):.3g}); on '
            f'overflow the backends would disagree. Check the checkpoint '
            f'(a diverged training?) and that the input holds spikes (0 '
            f'and 1)')

    def forward(self, spikes: torch.Tensor) -> torch.Tensor:
        """Enhance ``spikes`` ``(B, T, H, W)`` into ``(B, T, H, W)`` floats
        of the module's dtype.

        ``spikes`` of any dtype are converted to the module's (exact for
        0/1 spikes): a ``.double()`` module computes in float64, a
        ``.half()`` or ``.bfloat16()`` one runs its band networks in that
        dtype (the wavelet transform stays float32) on the backends that
        support it; the others name the backend and the dtype.

        The same answer on every backend to bad numbers, before any backend
        runs: NaN or Inf in ``spikes`` raises ``ValueError``
        (:func:`~wgse_mmseg.core.checks.check_finite`), and so do weights
        that are not finite (naming the parameter) or whose activations
        could leave float32's range (:meth:`_check_range`)."""
        if not isinstance(spikes, torch.Tensor) or spikes.dim() != 4:
            raise ArgumentError(
                'WGSE', 'spikes', 'a tensor shaped (B, T, H, W)',
                tuple(spikes.shape) if isinstance(spikes, torch.Tensor)
                else spikes)
        batch, num_steps, height, width = spikes.shape
        if not num_steps:
            raise ArgumentError(
                'WGSE', "the spikes' time dimension T (B, T, H, W)",
                'at least 1 frame', tuple(spikes.shape))
        module_dtype = self.band_networks[0].output_convs[-1].weight.dtype
        dtype = (torch.float64 if module_dtype == torch.float64
                 else torch.float32)
        device_type = spikes.device.type
        if self.wavelet is None:
            analysis = synthesis = None
            lengths = [num_steps]
        else:
            # int(): under a tracer (the FLOP count) a shape is a tensor;
            # the matrices are constants of T either way
            analysis, synthesis, lengths = self._matrices(
                int(num_steps), spikes.device, dtype)

        # the layout the backend reads (:mod:`.band_network_backends`)
        rows = pixel_major(self.backend, self.band_networks, device_type)

        def coefficients(spikes):
            """``(B, C, P)``, ``P = H*W`` (the time steps without wavelets),
            pixel-major where ``rows``, else band-major."""
            with torch.autocast(device_type, enabled=False):
                signal = spikes.to(dtype).reshape(batch, num_steps,
                                                  height * width)
                if analysis is not None:
                    coeffs = _product(analysis, signal, rows)
                else:
                    coeffs = signal.mT.contiguous().mT if rows else signal
                return coeffs.to(module_dtype)

        self._check_range(spikes, analysis, synthesis)
        coeffs = coefficients(spikes)
        backend, self.backend_check = resolve_backend(
            self.backend, self.band_networks, coeffs, lengths)
        self.backend_in_use = backend.name
        with saved_as_recomputation(coeffs, spikes, coefficients):
            # the synthesis product below gives the band networks' output
            # a gradient of its own, which the backend may overwrite
            enhanced = backend.run(
                self.band_networks, coeffs, lengths, (height, width),
                output_grad_is_scratch=self.wavelet is not None)
        # freed before the synthesis: the backends keep what they need
        del coeffs
        with torch.autocast(device_type, enabled=False):
            if self.wavelet is not None:
                enhanced = _product(synthesis, enhanced.to(dtype), rows)
            out = enhanced.reshape(batch, num_steps, height, width).to(
                module_dtype)
        if self.output_norm is not None:
            if self.output_norm.training and out.numel() < 2:
                raise ValueError(
                    f'WGSE(output_norm=True) standardises a training batch '
                    f'by its own statistics and needs at least 2 values; '
                    f'got spikes shaped {tuple(spikes.shape)}')
            out = self.output_norm(out.reshape(batch, 1, -1)).reshape(
                batch, num_steps, height, width)
        return out.contiguous()
