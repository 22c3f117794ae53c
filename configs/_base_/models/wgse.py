# WGSE as the paper configures it (db8, 5 levels, zero padding, kernel 3,
# 32 hidden channels, 1-D temporal convolutions): the enhancer the *_wgse
# configs put into their SpikeSegDataPreProcessor.
wgse = dict(type='WGSE', dim=1, wavelet='db8', level=5, mode='zero',
            kernel_size=3, hidden_channels=32)
