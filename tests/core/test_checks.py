"""The shared check of tensors: free of NaN and Inf."""
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from wgse_mmseg.core.checks import check_finite


@settings(max_examples=50, deadline=None)
@given(shape=st.lists(st.integers(1, 4), min_size=1, max_size=4),
       dtype=st.sampled_from([torch.float16, torch.float32, torch.float64]),
       data=st.data())
def test_check_finite_counts_like_numpy(shape, dtype, data):
    """Reference: NumPy's counts of NaN and of +-Inf in the same values."""
    size = int(np.prod(shape))
    values = np.array(data.draw(st.lists(
        st.sampled_from([0.0, 1.0, np.nan, np.inf, -np.inf]),
        min_size=size, max_size=size))).reshape(shape)
    tensor = torch.from_numpy(values).to(dtype)
    nan, inf = int(np.isnan(values).sum()), int(np.isinf(values).sum())
    if nan + inf == 0:
        check_finite('X', 'spikes', tensor)
        return
    with pytest.raises(ValueError) as info:
        check_finite('X', 'spikes', tensor)
    assert str(info.value).startswith(
        f'X: spikes holds {nan + inf} non-finite value(s) of {size} '
        f'({nan} NaN, {inf} +-Inf)')


@pytest.mark.parametrize('tensor', [
    torch.zeros(2, 3, dtype=torch.uint8), torch.ones(2, dtype=torch.bool),
    torch.full((2, ), 7, dtype=torch.int64), torch.zeros(0),
    torch.tensor([0.0, 1.0, 1e38, -1e38]),
])
def test_check_finite_passes_finite_and_integer_tensors(tensor):
    check_finite('X', 'spikes', tensor)
