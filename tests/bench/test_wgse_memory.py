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


def test_the_summary_is_the_medians_of_the_rounds_and_of_their_ratios():
    def row(kb, seconds):
        return dict(backend='compiled', kb_per_pixel=kb, median_s=seconds)

    rounds = [dict(new=row(2.0, 1.0), old=row(4.0, 4.0)),
              dict(new=row(3.0, 3.0), old=row(3.0, 2.0)),
              dict(new=row(2.5, 2.0), old=row(5.0, 1.0))]
    summary = wgse_memory.summarize(rounds, baseline='old')
    assert summary['new'] == dict(backend='compiled', kb_per_pixel=2.5,
                                  median_s=2.0, memory=0.5, time=1.5)
    # the ratios are each round's, not the ratio of the medians (2.0 / 2.0)
    assert summary['old'] == dict(backend='compiled', kb_per_pixel=4.0,
                                  median_s=2.0, memory=None, time=None)
    assert wgse_memory.summarize(rounds, baseline=None)['new']['time'] is None
