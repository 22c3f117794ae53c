# Table 5 ablation: the residual blocks alone, on the raw spike window.
_base_ = ['./wgse_resnet.py']
model = dict(enhancer=None)
