"""Spike data and WGSE without OpenMMLab.

This subpackage needs torch, NumPy, PyWavelets, OpenCV and PyYAML (all in
``install_requires``; Triton only for the GPU kernels). It imports and runs
where mmengine, mmseg and mmcv are not installed (a GPU machine without
OpenMMLab, a notebook), and importing it changes nothing outside it.

* :mod:`.constants`: the readout rate and the REDS intensity scale;
  :mod:`.limits`: the stated size limits the argument checks
  (:mod:`wgse_mmseg.argument_checks`) and the readers apply;
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

Importing it imports none of these: each name below, and each submodule,
is imported where it is first used, so that a command line's argument
parser (:mod:`wgse_mmseg.command_line`, :mod:`.limits`,
:mod:`.output_folder`) loads without torch, OpenCV or Triton.
"""
import importlib

#: public name -> the submodule that defines it
_NAMES = {
    'READOUT_HZ': 'constants', 'REDS_THRESHOLD': 'constants',
    'REDS_WHITE_RATE': 'constants', 'apply_exposure': 'exposure',
    'exposure_gain': 'exposure', 'SpikeFileError': 'spike_formats',
    'TFI': 'representations', 'TFP': 'representations',
    'SpatialMeanFilter': 'representations',
    'TemporalMeanFilter': 'representations',
    'simulate_spikes': 'simulation', 'wavedec': 'wavelets',
    'waverec': 'wavelets', 'WGSE': 'wgse', 'BandNetwork': 'wgse',
}

__all__ = [
    'SpikeFileError', 'TFI',
    'TFP', 'SpatialMeanFilter', 'TemporalMeanFilter', 'simulate_spikes',
    'wavedec', 'waverec', 'WGSE', 'apply_exposure'
]


def __getattr__(name):
    if name in _NAMES:
        module = importlib.import_module(f'{__name__}.{_NAMES[name]}')
    elif name.startswith('__'):
        raise AttributeError(name)
    else:  # a submodule not imported yet
        try:
            return importlib.import_module(f'{__name__}.{name}')
        except ModuleNotFoundError as err:
            if err.name != f'{__name__}.{name}':
                raise
            raise AttributeError(
                f'module {__name__!r} has no attribute {name!r}') from None
    value = globals()[name] = getattr(module, name)
    return value


def __dir__():
    return sorted(set(globals()) | set(_NAMES))
