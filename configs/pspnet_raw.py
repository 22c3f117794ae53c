# The paper's PSPNet baseline: raw spikes straight into the backbone.
_base_ = ['./pspnet_wgse.py']
model = dict(data_preprocessor=dict(enhancer=None))
