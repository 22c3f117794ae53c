"""The checks that need torch: tensor data free of NaN and Inf, a device.
(Plain arguments: :mod:`wgse_mmseg.argument_checks`.)"""
import torch

from ..argument_checks import ArgumentError

__all__ = []


def check_finite(owner: str, name: str, tensor: torch.Tensor) -> None:
    """Raise ``ValueError`` if ``tensor`` holds NaN or +-Inf.

    The one answer of the enhancers (WGSE on every backend, TFP, TFI, the
    mean filters) to non-finite input, given before any backend runs: the
    backends would otherwise disagree (NaN out of some, finite values out of
    others). The message names ``owner``, the argument ``name`` and how many
    values are not finite. Integer and bool tensors pass without a pass
    over the data; a float tensor costs one reduction (one device sync on a
    GPU). Skipped while ``torch.export`` traces (an ONNX export): a check
    of the values is data-dependent control flow, which no exported graph
    holds; what runs the exported graph checks its input instead
    (:class:`~wgse_mmseg.apis.onnx_segmentor.OnnxSpikeSegmentor`).
    Under ``torch.compile`` the check is part of the compiled graph and
    raises ``RuntimeError`` with the owner and name (no count).
    """
    if torch.compiler.is_exporting():
        return
    if not tensor.is_floating_point():
        return
    if torch.compiler.is_compiling():
        # the same check inside the compiled graph, where a Python branch
        # on a value would break it: a RuntimeError with this message
        torch._assert_async(
            torch.isfinite(tensor).all(),
            f'{owner}: {name} holds non-finite values (NaN or +-Inf); '
            f'spike streams hold 0 and 1')
        return
    if bool(torch.isfinite(tensor).all()):
        return
    bad = tensor.numel() - int(torch.isfinite(tensor).sum())
    nan = int(torch.isnan(tensor).sum())
    raise ValueError(
        f'{owner}: {name} holds {bad} non-finite value(s) of '
        f'{tensor.numel()} ({nan} NaN, {bad - nan} +-Inf); spike streams '
        f'hold 0 and 1, and no enhancer gives a meaningful result for NaN '
        f'or Inf')


def check_finite_parameters(owner: str, module: torch.nn.Module) -> None:
    """Raise ``ValueError`` naming the first float parameter or buffer of
    ``module`` that holds NaN or +-Inf (as a diverged training leaves), and
    how many of its values are not finite; return if all are finite.

    One reduction per tensor: for the diagnosis once a cheaper check (such
    as WGSE's activation bound) has found something wrong, not for every
    forward pass.
    """
    tensors = list(module.named_parameters()) + list(module.named_buffers())
    for name, tensor in tensors:
        if not tensor.is_floating_point():
            continue
        finite = torch.isfinite(tensor.detach())
        if bool(finite.all()):
            continue
        nan = int(torch.isnan(tensor.detach()).sum())
        bad = tensor.numel() - int(finite.sum())
        raise ValueError(
            f'{owner}: {name} is not finite ({nan} NaN, {bad - nan} +-Inf '
            f'of {tensor.numel()} values); the weights are broken (a '
            f'diverged training leaves them so): load a good checkpoint')


def check_device(entry: str, name: str, device) -> torch.device:
    """``device`` (a ``torch.device`` or its name, ``'cpu'``, ``'cuda:0'``)
    as a ``torch.device``; else an error naming ``entry`` and ``name``."""
    try:
        return torch.device(device)
    except (RuntimeError, TypeError, ValueError):
        raise ArgumentError(entry, name, "a torch device ('cpu', 'cuda', "
                            "'cuda:0', ...)", device) from None
