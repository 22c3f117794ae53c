"""The spike maths, without OpenMMLab and without file plumbing.

Needs torch, NumPy and PyWavelets (Triton only for the GPU kernels); runs
where mmengine, mmseg and mmcv are not installed (a GPU machine without
OpenMMLab, a notebook), reads and writes no file, and importing it changes
nothing outside it. Files are :mod:`wgse_mmseg.fileio`'s.

* :mod:`.wavelets`: the DWT as matrices, equal to PyWavelets';
* :mod:`.wgse`: WGSE, its band-network backends and kernels;
* :mod:`.representations`: TFP, TFI and the mean filters as modules
  ``(B, T, H, W) -> (B, T, H, W)``; :mod:`.reconstruction_baselines`: TFP
  and TFI images of one window; :mod:`.exposure`: exposure normalisation
  of such images; :mod:`.image_values`: what an image array means;
* :mod:`.simulation`: frames to spike streams, with sensor and camera
  effects;
* :mod:`.spike_formats`: what the bytes of each spike file format mean;
* :mod:`.enhancers`: the one list of enhancers; :mod:`.seeding`: the one
  seed range, check and derivation rule; :mod:`.constants`: the readout
  rate and the REDS intensity scale; :mod:`.checks`: finite tensors;
  :mod:`.parallel`: independent CPU work on torch's threads.

The names below are imported where first used, not with the package: the
torch-free modules (:mod:`.spike_formats`, :mod:`.image_values`) are read by
the file plumbing and the tools' argument parsers, which must start without
torch. Every name reachable here is in ``__all__``.
"""
import importlib

#: public name -> the submodule that defines it
_NAMES = {
    'SpikeFileError': 'spike_formats', 'apply_exposure': 'exposure',
    'TFI': 'representations', 'TFP': 'representations',
    'SpatialMeanFilter': 'representations',
    'TemporalMeanFilter': 'representations',
    'simulate_spikes': 'simulation', 'wavedec': 'wavelets',
    'waverec': 'wavelets', 'WGSE': 'wgse',
}

__all__ = list(_NAMES)


def __getattr__(name):
    if name not in _NAMES:
        raise AttributeError(
            f'module {__name__!r} has no attribute {name!r}')
    value = globals()[name] = getattr(
        importlib.import_module(f'{__name__}.{_NAMES[name]}'), name)
    return value


def __dir__():
    return sorted(set(globals()) | set(_NAMES))
