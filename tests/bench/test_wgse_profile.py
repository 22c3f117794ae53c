"""The profile of one WGSE pass: every millisecond a named kernel or a gap,
and the band kernels' TFLOP/s, from hand-made kernel intervals (the
profiling itself needs a GPU: the GPU report runs it)."""
import pytest

from wgse_bench import wgse_profile
from wgse_bench.wgse_profile import Interval


def test_shares_gaps_and_band_kernel_throughput_by_hand():
    intervals = [
        Interval('gemm', 0, 1000),                  # the analysis product
        Interval('band_forward_0d1d2d', 1500, 3500),
        Interval('band_forward_0d1d2d', 4000, 6000),   # a second launch
        Interval('band_backward_0d1d2d', 5500, 10000),  # overlaps 500 us
    ]
    summary = wgse_profile.summarize(intervals, positions=10**8, hidden=32,
                                     peak=500.0)
    assert summary['span_ms'] == 10.0
    # uncovered: 1000-1500 and 3500-4000
    assert summary['gaps_ms'] == pytest.approx(1.0)
    rows = {r['kernel']: r for r in summary['rows']}
    assert [r['kernel'] for r in summary['rows']] == [
        'band_backward_0d1d2d', 'band_forward_0d1d2d', 'gemm']
    assert rows['band_forward_0d1d2d']['launches'] == 2
    assert rows['band_forward_0d1d2d']['ms'] == pytest.approx(4.0)
    assert rows['gemm']['share'] == pytest.approx(0.1)
    assert 'tflops' not in rows['gemm']
    # forward: 2 x 3 x 32 x 32 FLOPs a position, twice, in 4 ms
    forward = 2 * 2 * 3 * 32 * 32 * 1e8 / 4e-3 / 1e12
    assert rows['band_forward_0d1d2d']['tflops'] == pytest.approx(forward)
    backward = 3 * 2 * 3 * 32 * 32 * 1e8 / 4.5e-3 / 1e12
    assert rows['band_backward_0d1d2d']['tflops'] == pytest.approx(backward)
    assert rows['band_backward_0d1d2d']['of_peak'] == pytest.approx(
        backward / 500)
    lines = wgse_profile.table_lines(summary)
    assert lines[-1].startswith('| gaps between kernels | | 1.000 | 10.0%')


def test_no_kernels_and_unknown_devices():
    assert wgse_profile.summarize([], 10, 32, None) == dict(
        span_ms=0.0, gaps_ms=0.0, rows=[])
    summary = wgse_profile.summarize([Interval('band_backward', 0, 10)],
                                     10, 32, None)
    assert summary['rows'][0]['of_peak'] is None
    assert wgse_profile.peak_tflops('NVIDIA GeForce RTX 4090', 'tf32') \
        is None


@pytest.mark.parametrize('name, precision, peak', [
    ('NVIDIA H100 80GB HBM3', 'tf32', 494.7),
    ('NVIDIA H200', 'bf16', 989.4),
    ('NVIDIA GH200 480GB', 'bf16', 989.4),
    # variants of a name: the PCIe and NVL boards run slower clocks
    ('NVIDIA H100 PCIe', 'tf32', 378.0),
    ('NVIDIA H100 PCIe', 'bf16', 756.0),
    ('NVIDIA H100 NVL', 'fp16', 835.0),
    ('NVIDIA H200 NVL', 'tf32', 417.5),
    ('NVIDIA B200', 'tf32', 1125.0),
    ('NVIDIA GB200', 'bf16', 2500.0),
    ('NVIDIA A100-SXM4-80GB', 'tf32', 156.0),
    ('NVIDIA A100 80GB PCIe', 'bf16', 312.0),
])
def test_peaks_of_board_variants(name, precision, peak):
    assert wgse_profile.peak_tflops(name, precision) == peak


def test_profiling_needs_a_gpu():
    with pytest.raises(ValueError, match='needs a CUDA device'):
        wgse_profile.profile_pass((1, 9, 2, 2), 'cpu')
