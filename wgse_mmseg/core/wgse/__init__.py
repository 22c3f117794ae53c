"""WGSE and what runs its band networks.

* :mod:`.wgse`: the module, :class:`WGSE` ``(B, T, H, W) -> (B, T, H, W)``,
  and its per-band network :class:`BandNetwork`;
* :mod:`.band_network_backends`: the ``backend`` choice (``'auto'``,
  ``'torch'``, ``'compiled'``, ``'triton'``, and ``'reference'``, the
  ``nn.Conv`` modules themselves, for tests), one interface;
* :mod:`.first_use_check`: a device kernel checked against ``'torch'`` in
  float64 before its first use in a process;
* the kernels behind it: :mod:`.torch_band_networks` (torch operations),
  :mod:`.compiled_band_networks` (the C extension ``_band_networks.c``),
  :mod:`.triton_band_networks` (CUDA; kernels in :mod:`.triton_band_kernels`).
"""
from .band_network_backends import BACKENDS, CHOICES, BandNetworkBackend
from .band_network import BandNetwork
from .wgse import WGSE

__all__ = ['WGSE']
