"""What WGSE's backward recomputes instead of keeping: saved-tensor hooks
that recognise the tensors autograd would save which are cheap functions of
the spikes (the wavelet coefficients, in any layout a backend reads, and
views of them) and store the spikes instead, remaking the tensor when the
backward asks for it.
"""
import contextlib
from typing import Callable, Tuple

import torch

__all__ = []


def saved_as_recomputation(tensor: torch.Tensor, source: torch.Tensor,
                           recompute: Callable[[torch.Tensor], torch.Tensor]):
    """Autograd hooks under which a saved tensor that views all of
    ``tensor``'s elements (the same storage, offset and number of elements:
    ``tensor`` itself, or a transpose or reshape of it, as a kernel's rows)
    is kept as ``source`` and made again in the backward pass, as the same
    view of ``recompute(source)``; every other saved tensor is kept as
    usual. WGSE's wavelet coefficients ``(B, C, P)`` are larger than the
    float32 spikes (``C`` exceeds ``T``); a band-network backend that saves
    them for its backward pass would hold them from the forward pass until
    WGSE's backward, through the whole segmentor's. ``source`` (the spikes)
    is held anyway; changed in place before the backward pass, it is
    refused as autograd refuses a changed saved tensor. No hooks where no
    autograd graph of real tensors is built (:func:`_records_autograd`)."""
    if not _records_autograd():
        return contextlib.nullcontext()
    version = source._version
    # what identifies the elements, not the tensor: torch keeps the hooks
    # as long as what they saved, which must not keep ``tensor`` alive
    elements = _elements(tensor)

    def pack(saved):
        if _elements(saved) != elements:
            return saved
        return _Recomputed(source, saved.shape, saved.stride())

    def unpack(packed):
        if not isinstance(packed, _Recomputed):
            return packed
        if packed.source._version != version:
            raise RuntimeError(
                'WGSE: the spikes were modified in place after the forward '
                'pass; its backward pass computes the wavelet coefficients '
                'from them again. Pass a copy, or modify them after '
                'backward()')
        # the same function of the same input: the same strides as
        # ``tensor``, so the saved view's strides select the same elements
        made = recompute(packed.source)
        return made.as_strided(packed.shape, packed.stride,
                               made.storage_offset())

    return torch.autograd.graph.saved_tensors_hooks(pack, unpack)


def _records_autograd() -> bool:
    """Whether this call builds an autograd graph of real tensors: not under
    ``no_grad``, nor traced or exported (``torch.export``'s fake tensors
    have no data pointer for :func:`_elements`)."""
    return torch.is_grad_enabled() and not (
        torch.jit.is_tracing() or torch.compiler.is_compiling())


def _elements(tensor: torch.Tensor) -> tuple:
    """Which elements ``tensor`` views: two tensors alike here view the
    same elements (in orders their strides say)."""
    return (tensor.untyped_storage().data_ptr(), tensor.storage_offset(),
            tensor.numel(), tensor.dtype, tensor.device)


class _Recomputed:
    """What a saved tensor under :func:`saved_as_recomputation` is kept
    as: its source, and the view of the recomputed tensor it was."""

    def __init__(self, source: torch.Tensor, shape: torch.Size,
                 stride: Tuple[int, ...]):
        self.source = source
        self.shape = shape
        self.stride = stride
