"""The published model data NIQE and BRISQUE need, shipped in ``data/``.

Made by ``dev/extract_quality_models.py`` from pinned registry
packages (basicsr 1.4.2, brisque 0.2.0, both Apache-2.0: their licences lie
beside the files) and recorded with their SHA-256 in ``data/SOURCES.json``;
nothing is downloaded at run time and no pickle is read (``.npz`` files are
loaded with ``allow_pickle=False``, the rest is JSON).
"""
import functools
import os.path as osp
from typing import NamedTuple

import numpy as np

from ...fileio.bounded_reads import load_json_file

__all__ = []

DATA_DIR = osp.join(osp.dirname(osp.abspath(__file__)), 'data')
#: the record of the shipped files: name -> SHA-256, size and source
SOURCES = osp.join(DATA_DIR, 'SOURCES.json')
NUM_FEATURES = 36


class NiqeModel(NamedTuple):
    """NIQE's multivariate Gaussian of pristine images' features."""
    #: ``(36,)`` mean feature vector
    mean: np.ndarray
    #: ``(36, 36)`` feature covariance
    covariance: np.ndarray
    #: ``(7, 7)`` local-moment weights (a Gaussian, sums to 1)
    window: np.ndarray


class BrisqueModel(NamedTuple):
    """BRISQUE's feature scaling and RBF epsilon-SVR (libsvm's)."""
    #: ``(36,)`` each feature's value mapped to -1 and ...
    feature_min: np.ndarray
    #: ``(36,)`` ... to +1
    feature_max: np.ndarray
    #: ``(N, 36)`` support vectors (scaled features)
    support_vectors: np.ndarray
    #: ``(N,)`` their coefficients
    dual_coef: np.ndarray
    #: the decision function's offset (score = coef . K - rho)
    rho: float
    #: the kernel's ``exp(-gamma |x - v|**2)`` width
    gamma: float


def _load(name: str) -> dict:
    """The float64 arrays of the shipped ``.npz`` file ``name``."""
    path = osp.join(DATA_DIR, name)
    try:
        with np.load(path, allow_pickle=False) as data:
            return {key: data[key].astype(np.float64) for key in data.files}
    except (OSError, ValueError) as err:
        raise RuntimeError(f'{path}: cannot read the shipped model data '
                           f'({err}); reinstall wgse_mmseg') from err


def _check(name: str, arrays: dict, shapes: dict) -> None:
    found = {key: value.shape for key, value in arrays.items()}
    if found != shapes:
        raise RuntimeError(f'{osp.join(DATA_DIR, name)}: expected arrays '
                           f'{shapes}, found {found}; reinstall wgse_mmseg')


@functools.lru_cache(maxsize=1)
def niqe_model() -> NiqeModel:
    """The NIQE MATLAB release's pristine model (basicsr 1.4.2's copy)."""
    name = 'niqe_pristine_model.npz'
    arrays = _load(name)
    _check(name, arrays, {'mu_pris_param': (1, NUM_FEATURES),
                          'cov_pris_param': (NUM_FEATURES, NUM_FEATURES),
                          'gaussian_window': (7, 7)})
    return NiqeModel(arrays['mu_pris_param'][0], arrays['cov_pris_param'],
                     arrays['gaussian_window'])


@functools.lru_cache(maxsize=1)
def brisque_model() -> BrisqueModel:
    """brisque 0.2.0's trained model."""
    name = 'brisque_svr_model.npz'
    arrays = _load(name)
    count = len(arrays.get('dual_coef', ()))
    _check(name, arrays, {'support_vectors': (count, NUM_FEATURES),
                          'dual_coef': (count, ), 'rho': (), 'gamma': ()})
    name = 'brisque_feature_range.json'
    limits = {key: np.array(value, np.float64) for key, value in
              load_json_file(osp.join(DATA_DIR, name), 'model file').items()}
    _check(name, limits, {'min': (NUM_FEATURES, ), 'max': (NUM_FEATURES, )})
    return BrisqueModel(limits['min'], limits['max'],
                        arrays['support_vectors'], arrays['dual_coef'],
                        float(arrays['rho']), float(arrays['gamma']))
