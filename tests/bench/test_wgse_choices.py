"""The benchmarks' torch-free choices name what the kernels are built for."""
from wgse_bench import wgse_choices
from wgse_mmseg.core.wgse import triton_band_networks


def test_the_precisions_are_the_kernels_checked_precisions():
    assert sorted(wgse_choices.PRECISIONS) == sorted(
        triton_band_networks.TOLERANCES)


def test_the_hidden_widths_are_the_kernels():
    assert wgse_choices.HIDDEN_CHANNELS == \
        triton_band_networks.HIDDEN_CHANNELS
