# Table 5 ablation: "TRCNN without wavelets": one band network of WGSE on the
# raw stream (no wavelet transform), then the residual blocks.
_base_ = ['./wgse_resnet.py']
model = dict(enhancer=dict(wavelet=None))
