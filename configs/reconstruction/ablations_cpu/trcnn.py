# The equal-budget ablation of wgse_1d.py (see there) without wavelets: the
# temporal residual CNN on the raw time series, WGSE(wavelet=None).
_base_ = ['./wgse_1d.py']
model = dict(enhancer=dict(wavelet=None))
