# The full experiment grid with the paper's data settings (Spike-Cityscapes:
# T=129, 256x512 crops, 100 epochs); needs a GPU. Extends grid_cpu.py: the
# same models and representations, TFP's window again about half of T, and
# the wavelet sweep crossed in full (db1, db4, db8, sym4, coif2 at 1 to 5
# levels).
_base_ = ['./grid_cpu.py']

enhancers = dict(
    tfp=dict(type='TFP', window=65),
    **{f'wgse1d_{w}_l{n}': dict(type='WGSE', dim=1, wavelet=w, level=n)
       for w in ('db1', 'db4', 'sym4', 'coif2') for n in (1, 2, 3, 4)},
)
cfg_options = dict(num_steps=129, crop_size='256,512')
epochs = 100
