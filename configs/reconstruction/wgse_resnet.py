# The paper's reconstruction model: WGSE (db8, 5 levels) in front of a 3x3
# conv to 256 channels, ReLU, three residual blocks, a conv to 64, ReLU and a
# conv to one grey channel; L1 loss. Trained on spikes simulated from images
# (128x128 crops, batch 8, Adam 1e-4, 100k iterations: GPU-sized; see
# wgse_resnet_cpu.py for the CPU-sized run that made the shipped weights).
_base_ = [
    './_base_/datasets/simulated_train.py',
    './_base_/schedules/adam_iters.py',
]
model = dict(
    type='SpikeReconstructor',
    num_steps={{_base_.num_steps}},
    enhancer=dict(type='WGSE', dim=1, wavelet='db8', level=5, mode='zero',
                  kernel_size=3, hidden_channels=32, num_blocks=1),
    channels=256,
    num_blocks=3,
    mid_channels=64,
    data_preprocessor=dict(type='ImgDataPreprocessor'))
