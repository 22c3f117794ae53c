# The paper's SegFormer-B0 baseline: raw spikes straight into the backbone.
_base_ = ['./segformer_b0_wgse.py']
model = dict(data_preprocessor=dict(enhancer=None))
