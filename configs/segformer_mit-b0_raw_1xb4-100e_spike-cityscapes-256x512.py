# The paper's SegFormer-B0 baseline: raw spikes straight into the backbone.
_base_ = ['./segformer_mit-b0_wgse_1xb4-100e_spike-cityscapes-256x512.py']
model = dict(data_preprocessor=dict(enhancer=None))
