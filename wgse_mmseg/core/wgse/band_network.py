"""One band's network: the small temporal residual CNN WGSE runs on each
wavelet band (Conv1d 1 -> C, ReLU, residual layers of C -> C, Conv 1 -> 1,
ReLU; or their 2-D and 3-D forms), ``(N, 1, L) -> (N, 1, L)``.
"""
from typing import List, Optional, Tuple

import torch
import torch.nn as nn
import torch.nn.functional as F

__all__ = []


def _conv(dim: int, in_channels: int, out_channels: int,
          kernel_size: int) -> nn.Module:
    """The convolution of one variant, 'same' padded.

    Band tensors are ``(N, C, L)`` for ``dim=1`` and ``(B, C, L, H, W)`` for
    ``dim`` 2 and 3 (``L``: coefficients of the band).
    """
    pad = kernel_size // 2
    if dim == 1:
        return nn.Conv1d(in_channels, out_channels, kernel_size, padding=pad)
    if dim == 2:
        return nn.Conv3d(in_channels, out_channels, (1, kernel_size,
                                                     kernel_size),
                         padding=(0, pad, pad))
    return nn.Conv3d(in_channels, out_channels, kernel_size, padding=pad)


class _ResidualLayer(nn.Module):
    """``relu(conv_b(relu(conv_a(x))) + x)``; a 1-channel ``x`` broadcasts."""

    def __init__(self, dim: int, in_channels: int, channels: int,
                 kernel_size: int):
        super().__init__()
        self.conv_a = _conv(dim, in_channels, channels, kernel_size)
        self.conv_b = _conv(dim, channels, channels, kernel_size)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.conv_b(F.relu(self.conv_a(x))) + x)


class BandNetwork(nn.Module):
    """The per-band network: residual layers, then output convolutions.

    ``num_blocks`` residual layers (the first maps 1 to ``hidden_channels``
    channels), then ``num_blocks - 1`` ``hidden -> hidden`` convolutions and a
    final ``hidden -> 1`` convolution, each followed by ReLU. With
    ``num_blocks=1`` this is the paper's ``Conv 1->32, ReLU, Conv 32->32,
    + input, ReLU, Conv 32->1, ReLU``.

    Input and output: ``(N, 1, L)`` for ``dim=1``, ``(B, 1, L, H, W)`` else.
    A part of :class:`~wgse_mmseg.core.wgse.wgse.WGSE`, which checks the
    arguments.
    """

    def __init__(self, dim: int = 1, kernel_size: int = 3,
                 hidden_channels: int = 32, num_blocks: int = 1):
        super().__init__()
        self.dim = dim
        self.kernel_size = kernel_size
        self.hidden_channels = hidden_channels
        self.num_blocks = num_blocks
        self.residual_layers = nn.Sequential(*[
            _ResidualLayer(dim, 1 if i == 0 else hidden_channels,
                           hidden_channels, kernel_size)
            for i in range(num_blocks)
        ])
        self.output_convs = nn.ModuleList([
            _conv(dim, hidden_channels,
                  1 if i == num_blocks - 1 else hidden_channels, kernel_size)
            for i in range(num_blocks)
        ])

    @staticmethod
    def parameter_count(dim: int, kernel_size: int, hidden_channels: int,
                        num_blocks: int) -> int:
        """Parameters of a network of these arguments, without building
        it."""
        taps = kernel_size ** (1 if dim == 1 else 2 if dim == 2 else 3)
        hidden = hidden_channels * hidden_channels * taps + hidden_channels
        first = hidden_channels * taps + hidden_channels
        return (first + hidden  # the first residual layer
                + (num_blocks - 1) * 3 * hidden  # further layers, outputs
                + hidden_channels * taps + 1)  # the last output convolution

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.residual_layers(x)
        for conv in self.output_convs:
            x = F.relu(conv(x))
        return x

    @torch.no_grad()
    def init_pass_through(self, gain: float, bias: float = 0.0) -> None:
        """Set the weights so that the network computes
        ``relu(gain * relu(x) + bias)`` for input ``x`` (``(N, 1, L)`` or
        ``(B, 1, L, H, W)``): every residual branch is zero (its second
        convolution's weights and bias; the first keeps its weights and
        learns once the second moves), the hidden output convolutions pass
        each channel through, and the last one averages the channels
        times ``gain`` and adds ``bias``."""
        for block in self.residual_layers:
            block.conv_b.weight.zero_()
            block.conv_b.bias.zero_()
        for index, conv in enumerate(self.output_convs):
            centre = tuple(size // 2 for size in conv.weight.shape[2:])
            conv.weight.zero_()
            conv.bias.zero_()
            if index < len(self.output_convs) - 1:
                for channel in range(self.hidden_channels):
                    conv.weight[(channel, channel) + centre] = 1.0
            else:
                conv.weight[(0, slice(None)) + centre] = (
                    gain / self.hidden_channels)
                conv.bias.fill_(bias)

    def layers(self) -> List[Tuple[nn.Module, Optional[int]]]:
        """The convolutions in order, each with the index of the activation
        added before its ReLU (0: the input, ``i``: the output of the
        ``i``-th convolution) or ``None``: the description
        :func:`~wgse_mmseg.core.wgse.torch_band_networks.torch_band_networks`
        runs."""
        plan = []
        for block in self.residual_layers:
            block_input = len(plan)
            plan += [(block.conv_a, None), (block.conv_b, block_input)]
        return plan + [(conv, None) for conv in self.output_convs]
