# Table 5 ablation: long WGSE (two residual layers and two output convs per
# band network), then the residual blocks.
_base_ = ['./wgse_resnet.py']
model = dict(enhancer=dict(num_blocks=2))
