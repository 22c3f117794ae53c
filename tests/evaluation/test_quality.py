"""No-reference image quality (wgse_mmseg.evaluation.quality): NIQE and BRISQUE
against their reference implementations, the shipped model data against
its record, and the measures' behaviour on any image.

Uses scikit-image's photographs (``skimage.data``, shipped in its wheel; no
download) as test images: scikit-image is needed by these tests only.
"""
import hashlib
import io
import json
import os.path as osp
import pickle
import zipfile
from collections import OrderedDict

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wgse_mmseg.evaluation.quality import (brisque, entropy_2d, niqe,
                                           no_reference_scores)
from wgse_mmseg.evaluation.quality.model_data import (DATA_DIR, SOURCES,
                                                      brisque_model,
                                                      niqe_model)
from wgse_mmseg.evaluation.quality.natural_scene import (fit_aggd_grid,
                                                         fit_aggd_root,
                                                         ggd_ratio)
from wgse_mmseg.evaluation.quality.niqe import matlab_half_size

skimage_data = pytest.importorskip('skimage.data')

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))

#: Reference scores of scikit-image 0.26.0's grey photographs
#: (``skimage.data.<name>()``, uint8), computed on 2026-11-24 with numpy
#: 2.4.6, scipy 1.17.1, torch 2.13 and OpenCV 4.14.0 by
#:
#: * NIQE: basicsr 1.4.2's ``basicsr/metrics/niqe.py`` and
#:   ``basicsr/utils/matlab_functions.py`` from its sdist, unchanged (the
#:   package's other modules stubbed so that they import),
#:   ``calculate_niqe(image.astype(float64), 0, input_order='HW')``;
#: * BRISQUE: brisque 0.2.0 from its wheel with libsvm-official 3.37.0
#:   (built by ``pip install --target``), ``BRISQUE(url=False).score(
#:   np.dstack([image] * 3))``, with one change: its ``scale_features`` calls
#:   ``float()`` on 1-element arrays, which numpy 2 refuses; the same
#:   arithmetic on ``.item()``.
#:
#: Images with flat regions (skimage's ``page``, ``cell``) are left out:
#: there the references' scores depend on the sign of their convolutions'
#: rounding noise (``natural_scene.FLAT``).
REFERENCE = {  # name: (NIQE, BRISQUE)
    'brick': (9.479599681810095, 39.3949529112426),
    'camera': (3.096206619345783, -7.879404294309921),
    'clock': (10.948337438521296, 39.10907778714429),
    'coins': (3.622671715936883, -1.5209755179437536),
    'grass': (6.492953323156384, 23.782147906872723),
    'gravel': (4.333703240190888, 27.516907964778596),
    'moon': (9.11205153111188, 18.81898136517438),
    'text': (10.197638378265873, 31.870336604611538),
}
#: basicsr computes NIQE in float32 (this package in float64): its grid
#: search for the AGGD shape can land a step (0.001) apart
NIQE_TOLERANCE = 2e-3
#: brisque 0.2.0 solves for the shape to about 1e-8; camera has a few flat
#: pixels whose rounding-noise sign it counts
BRISQUE_TOLERANCE = 1e-3


@pytest.mark.parametrize('name', sorted(REFERENCE))
def test_niqe_and_brisque_match_their_reference_implementations(name):
    image = getattr(skimage_data, name)()
    reference_niqe, reference_brisque = REFERENCE[name]
    assert abs(niqe(image) - reference_niqe) < NIQE_TOLERANCE
    assert abs(brisque(image) - reference_brisque) < BRISQUE_TOLERANCE


def test_the_shipped_model_files_match_their_record():
    with open(SOURCES) as f:
        record = json.load(f)
    assert set(record) == {'niqe_pristine_model.npz', 'brisque_svr_model.npz',
                           'brisque_feature_range.json',
                           'LICENSE.basicsr.txt', 'LICENSE.brisque.txt'}
    for name, entry in record.items():
        with open(osp.join(DATA_DIR, name), 'rb') as f:
            data = f.read()
        assert len(data) == entry['size'], name
        assert hashlib.sha256(data).hexdigest() == entry['sha256'], name
    # copied byte for byte from basicsr's sdist
    niqe_entry = record['niqe_pristine_model.npz']
    assert niqe_entry['sha256'] == niqe_entry['member_sha256']
    assert niqe_entry['package'] == 'basicsr==1.4.2'
    assert record['brisque_svr_model.npz']['package'] == 'brisque==0.2.0'


def test_the_shipped_models_load_without_pickles():
    niqe_data = niqe_model()
    assert niqe_data.mean.shape == (36, )
    np.testing.assert_allclose(niqe_data.covariance, niqe_data.covariance.T)
    assert abs(niqe_data.window.sum() - 1) < 1e-9
    svr = brisque_model()
    assert svr.support_vectors.shape == (770, 36)
    assert svr.gamma == 0.05 and svr.rho == -155.845  # svm.txt's header
    assert (svr.feature_max > svr.feature_min).all()
    # every .npz there loads with pickles refused
    for name in ('niqe_pristine_model.npz', 'brisque_svr_model.npz'):
        with np.load(osp.join(DATA_DIR, name), allow_pickle=False) as data:
            assert all(data[k].dtype == np.float64 for k in data.files)


def test_matlab_half_size_by_hand():
    """Constant stays constant; on a ramp, MATLAB's symmetric kernel gives
    the mean of the two input pixels an output pixel covers (inside, away
    from the mirrored border)."""
    np.testing.assert_allclose(matlab_half_size(np.full((8, 12), 7.0)),
                               np.full((4, 6), 7.0))
    ramp = np.tile(np.arange(16.0), (6, 1))
    half = matlab_half_size(ramp)
    assert half.shape == (3, 8)
    np.testing.assert_allclose(half[:, 2:6], np.tile(
        [4.5, 6.5, 8.5, 10.5], (3, 1)), atol=1e-12)


@pytest.mark.parametrize('shape, fit', [(2.0, fit_aggd_grid),
                                        (2.0, fit_aggd_root),
                                        (1.0, fit_aggd_grid),
                                        (1.0, fit_aggd_root)])
def test_aggd_fits_recover_a_known_shape(shape, fit):
    """Gaussian samples have shape 2, Laplacian samples shape 1."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=200_000) if shape == 2 else rng.laplace(
        size=200_000)
    assert abs(fit(x).alpha - shape) < 0.05
    assert fit(np.abs(x)) is None  # one-sided: nothing to fit


def test_ggd_ratio_is_increasing_with_known_values():
    assert abs(ggd_ratio(2.0) - 2 / np.pi) < 1e-12  # Gaussian: (E|x|)^2/Ex^2
    assert abs(ggd_ratio(1.0) - 0.5) < 1e-12  # Laplacian
    values = ggd_ratio(np.geomspace(0.05, 50, 200))
    assert (np.diff(values) > 0).all() and values[-1] < 0.75


def test_distortion_scores_worse():
    image = skimage_data.camera()
    blurred = cv2.GaussianBlur(image, (0, 0), 2)
    noisy = np.clip(image + np.random.default_rng(0).normal(
        0, 20, image.shape), 0, 255).astype(np.uint8)
    for distorted in (blurred, noisy):
        assert niqe(distorted) > niqe(image) + 1
        assert brisque(distorted) > brisque(image) + 10


def test_float_and_uint8_images_score_alike():
    image = skimage_data.coins()
    assert niqe(image / 255.0) == niqe(image)
    assert brisque(image.astype(np.float32) / 255) == brisque(image)


@pytest.mark.parametrize('image, match', [
    (np.full((200, 200), 0.5), 'texture'),
    (np.zeros((95, 400)), 'two 96x96 blocks'),
    (np.zeros((96, 150)), 'two 96x96 blocks')])
def test_niqe_refuses_what_it_cannot_score(image, match):
    with pytest.raises(ValueError, match=match):
        niqe(image)


@pytest.mark.parametrize('image, match', [
    (np.full((50, 50), 0.3), 'without texture'),
    (np.random.default_rng(0).random((13, 50)), 'at least 14x14')])
def test_brisque_refuses_what_it_cannot_score(image, match):
    with pytest.raises(ValueError, match=match):
        brisque(image)


@pytest.mark.parametrize('image', [np.zeros((3, 4, 5)), np.zeros((0, 5)),
                                   np.full((200, 200), np.nan),
                                   np.array([['a']])])
def test_malformed_images_are_errors_everywhere(image):
    for measure in (niqe, brisque, entropy_2d, no_reference_scores):
        with pytest.raises(ValueError, match='image'):
            measure(image)


def test_no_reference_scores_says_none_where_undefined():
    scores = no_reference_scores(np.full((120, 240), 0.5))
    assert scores == {'NIQE': None, 'BRISQUE': None, 'Entropy2D': 0.0}
    image = skimage_data.coins()
    assert no_reference_scores(image) == {
        'NIQE': niqe(image), 'BRISQUE': brisque(image),
        'Entropy2D': entropy_2d(image)}


@settings(max_examples=15, deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(height=st.integers(96, 200), width=st.integers(192, 260),
       seed=st.integers(0, 2**16), sigma=st.floats(0.0, 3.0),
       brightness=st.floats(0.05, 1.0))
def test_scores_are_finite_on_any_textured_image(height, width, seed, sigma,
                                                 brightness):
    rng = np.random.default_rng(seed)
    image = rng.random((height, width))
    if sigma > 0:
        image = cv2.GaussianBlur(image, (0, 0), sigma)
    image = image / image.max() * brightness
    scores = no_reference_scores(image)
    for name in ('NIQE', 'BRISQUE'):
        assert scores[name] is None or np.isfinite(scores[name]), name
    # random texture always has it; only flat 8-bit blocks could lack it
    assert scores['BRISQUE'] is not None
    assert 0 < scores['Entropy2D'] <= 16


# ------------------------------------------- the model files' extraction
def test_extraction_refuses_a_pickle_that_imports(load_tool):
    tool = load_tool('dev/extract_quality_models.py')
    plain = {'min_': [0.5] * 36, 'max_': [1.5] * 36}
    assert tool.feature_range(pickle.dumps(plain)) == {
        'min': [0.5] * 36, 'max': [1.5] * 36}
    with pytest.raises(pickle.UnpicklingError, match='refused'):
        tool.feature_range(pickle.dumps(OrderedDict(plain)))
    with pytest.raises(ValueError, match='36 floats'):
        tool.feature_range(pickle.dumps({'min_': [1.0], 'max_': [2.0]}))


def test_extraction_parses_libsvm_text_and_writes_a_fixed_npz(load_tool):
    tool = load_tool('dev/extract_quality_models.py')
    text = ('svm_type epsilon_svr\nkernel_type rbf\ngamma 0.05\nnr_class 2\n'
            'total_sv 2\nrho -1.5\nSV\n-1024 1:0.25 36:-0.5 \n'
            '3.5 2:0.125 \n')
    model = tool.svr_model(text)
    assert model['support_vectors'].shape == (2, 36)
    assert model['support_vectors'][0, 0] == 0.25
    assert model['support_vectors'][0, 35] == -0.5
    assert model['support_vectors'][1, 1] == 0.125
    assert model['support_vectors'].sum() == 0.25 - 0.5 + 0.125
    assert list(model['dual_coef']) == [-1024, 3.5] and model['rho'] == -1.5
    with pytest.raises(ValueError, match='header says 3'):
        tool.svr_model(text.replace('total_sv 2', 'total_sv 3'))
    data = tool.npz_bytes(model)
    assert data == tool.npz_bytes(model)  # the same bytes every time
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        assert {i.date_time for i in archive.infolist()} == {
            (1980, 1, 1, 0, 0, 0)}
    with np.load(io.BytesIO(data), allow_pickle=False) as arrays:
        assert arrays['rho'].shape == ()
        np.testing.assert_array_equal(arrays['support_vectors'],
                                      model['support_vectors'])
