# The equal-budget ablation of wgse_1d.py (see there) without an enhancer:
# the residual network on the raw spikes.
_base_ = ['./wgse_1d.py']
model = dict(enhancer=None)
