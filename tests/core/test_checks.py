"""The shared integer check."""
import numpy as np
import pytest

from wgse_mmseg.core.checks import is_integer


@pytest.mark.parametrize('value, minimum, expected', [
    (3, None, True), (3, 3, True), (2, 3, False), (0, 0, True),
    (-1, 0, False), (np.int64(5), 1, True), (np.uint8(0), 1, False),
    (True, None, False), (False, 0, False), (2.0, None, False),
    (2.5, 1, False), ('3', None, False), (None, None, False),
    (2**80, 1, True),
])
def test_is_integer(value, minimum, expected):
    assert is_integer(value, minimum) is expected
