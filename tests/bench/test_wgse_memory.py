"""The training-pass memory benchmark: its figures, and a failed worker
named."""
import pytest

from wgse_bench import wgse_memory


def test_the_worker_reports_the_backend_that_ran_and_its_figures():
    result = wgse_memory.worker('torch', [1, 9, 6, 5], repeat=2)
    assert result['backend'] == 'torch'
    # growth of a peak is never negative; two timed passes took time
    assert result['kb_per_pixel'] >= 0 and result['median_s'] > 0


def test_a_failing_worker_is_an_error_with_its_command_and_stderr():
    with pytest.raises(RuntimeError, match="backend must be one of"):
        wgse_memory.measure('no-such-backend', [1, 9, 4, 4], 1)
