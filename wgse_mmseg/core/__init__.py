"""Spike data and WGSE without OpenMMLab.

This subpackage needs torch, NumPy, PyWavelets, OpenCV and PyYAML (all in
``install_requires``; Triton only for the GPU kernels). It imports and runs
where mmengine, mmseg and mmcv are not installed (a GPU machine without
OpenMMLab, a notebook), and importing it changes nothing outside it.

* :mod:`.constants`: the readout rate and the REDS intensity scale;
  :mod:`.arguments`: the declared argument checks of the public entry
  points; :mod:`.limits`: the stated size limits they apply;
* :mod:`.io`: spike files (``.dat``, ``.spk``, ``.npy``, ``.npz``) and
  atomic writes;
* :mod:`.wavelets`: the DWT as matrices, equal to PyWavelets';
* :mod:`.enhancers`: the one list of enhancers (WGSE and the classical
  representations); :mod:`.seeding`: the one seed range, check and
  derivation rule;
* :mod:`.representations`: TFP, TFI and the mean filters as modules
  ``(B, T, H, W) -> (B, T, H, W)``; :mod:`.reconstruction_baselines`: TFP
  and TFI images of one window; :mod:`.exposure`: exposure normalisation
  of such images;
* :mod:`.wgse`: WGSE, its band-network backends and kernels;
* :mod:`.simulation`: frames to spike streams, with sensor and camera
  effects;
* :mod:`.parallel`: independent CPU work on torch's threads.

The MMSeg layer (``wgse_mmseg.datasets``, ``.models``, ``.evaluation``)
registers these with MMSeg's registries.
"""
from .constants import READOUT_HZ, REDS_THRESHOLD, REDS_WHITE_RATE
from .exposure import apply_exposure, exposure_gain
from .io import SpikeFileError, load_spikes, save_spikes, spike_shape
from .representations import (TFI, TFP, SpatialMeanFilter,
                              TemporalMeanFilter)
from .simulation import simulate_spikes
from .wavelets import wavedec, waverec
from .wgse import WGSE, BandNetwork

__all__ = [
    'SpikeFileError', 'load_spikes', 'save_spikes', 'spike_shape', 'TFI',
    'TFP', 'SpatialMeanFilter', 'TemporalMeanFilter', 'simulate_spikes',
    'wavedec', 'waverec', 'WGSE', 'apply_exposure'
]
