# The paper's PSPNet baseline: raw spikes straight into the backbone.
_base_ = ['./pspnet_r50-d8_wgse_1xb4-100e_spike-cityscapes-256x512.py']
model = dict(data_preprocessor=dict(enhancer=None))
