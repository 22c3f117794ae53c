"""Every band-network backend gives one answer to bad numbers: weights or
spikes that are not finite, or large enough that float32 overflows, raise
the same ``ValueError`` (naming the parameter) on every backend, and tiny
(denormal) weights give the same values on every backend. The Triton
kernel runs in triton's CPU interpreter (``conftest.py``)."""
import re

import pytest
import torch

from wgse_mmseg.core.wgse import WGSE, band_network_backends

pytestmark = pytest.mark.usefixtures('single_thread')

BACKENDS = ['auto'] + [
    name for name, backend in band_network_backends.BACKENDS.items()
    if backend.unavailable() is None]
#: a weight inside the fourth band's network
WEIGHT = 'band_networks.3.residual_layers.0.conv_a.weight'


def _set_one(value):
    def change(model, spikes):
        with torch.no_grad():
            model.get_parameter(WEIGHT)[1, 0, 2] = value
        return spikes
    return change


def _scale(factor):
    def change(model, spikes):
        with torch.no_grad():
            for parameter in model.parameters():
                parameter.mul_(factor)
        return spikes
    return change


def _fill_spikes(value):
    def change(model, spikes):
        spikes = spikes.clone()
        spikes[0, 4, 1, 2] = value
        return spikes
    return change


#: case -> (change of model and spikes, the error's text or None: a value)
CASES = {
    'nan weight': (_set_one(float('nan')),
                   WEIGHT + r' is not finite \(1 NaN, 0 \+-Inf of 96'),
    'inf weight': (_set_one(float('inf')),
                   WEIGHT + r' is not finite \(0 NaN, 1 \+-Inf of 96'),
    '-inf weight': (_set_one(-float('inf')),
                    WEIGHT + r' is not finite \(0 NaN, 1 \+-Inf of 96'),
    'weights x1e25': (_scale(1e25), "could exceed float32's range"),
    'denormal weights': (_scale(1e-40), None),
    'nan spike': (_fill_spikes(float('nan')),
                  'spikes holds 1 non-finite value'),
    'huge spike': (_fill_spikes(3e38), "could exceed float32's range"),
    'large finite spike': (_fill_spikes(1e6), None),
}


def _outcome(backend, change):
    torch.manual_seed(0)
    model = WGSE(backend=backend)
    spikes = change(model, (torch.rand(1, 41, 3, 7) < 0.3).float())
    try:
        return model(spikes).detach()
    except ValueError as error:
        return error


@pytest.mark.parametrize('case', CASES)
def test_every_backend_gives_one_answer(case):
    change, error = CASES[case]
    outcomes = {backend: _outcome(backend, change) for backend in BACKENDS}
    reference = outcomes['reference']
    if error is not None:
        assert isinstance(reference, ValueError)
        assert re.search(error, str(reference)), str(reference)
    else:
        assert isinstance(reference, torch.Tensor)
        assert bool(torch.isfinite(reference).all())
        assert bool(reference.abs().max() > 0)
    for backend, outcome in outcomes.items():
        assert type(outcome) is type(reference), (backend, outcome)
        if error is not None:
            assert str(outcome) == str(reference), backend
        else:
            scale = float(reference.abs().max())
            torch.testing.assert_close(outcome, reference, rtol=1e-4,
                                       atol=1e-5 * scale, msg=backend)
