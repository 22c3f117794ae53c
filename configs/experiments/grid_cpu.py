# The experiment grid on the embedded dataset, sized for a CPU
# (tools/analysis_tools/run_experiments.py; docs/benchmark.md). Every entry is
# one of `models` with one of `enhancers` in front: the model's raw-spike
# config with `model.data_preprocessor.enhancer` overridden, nothing else
# changed. Entry names are `<model>_<enhancer>`, e.g.
# `segformer_b0_wgse1d_db4_l5`.

# model name -> config (relative to the repository root); enhancer None in
# each
models = dict(
    segformer_b0='configs/segformer_b0_raw.py',
    pspnet='configs/pspnet_raw.py',
)

# enhancer name -> `model.data_preprocessor.enhancer` (None: raw spikes)
enhancers = dict(
    raw=None,
    # classical representations (Zhu et al., ICME 2019); TFP's window is
    # about half the stream
    tfp=dict(type='TFP', window=21),
    tfi=dict(type='TFI'),
    # the mean-filter baselines of the WGSE paper's denoising comparison
    mean_spatial=dict(type='SpatialMeanFilter', kernel_size=3),
    mean_temporal=dict(type='TemporalMeanFilter', kernel_size=3),
    # WGSE as in the paper (db8, 5 levels), with 1-D, 2-D, 3-D convolutions
    wgse1d=dict(type='WGSE', dim=1, wavelet='db8', level=5),
    wgse2d=dict(type='WGSE', dim=2, wavelet='db8', level=5),
    wgse3d=dict(type='WGSE', dim=3, wavelet='db8', level=5),
    # wavelet sweep (WGSE 1-D): the other wavelets at 5 levels ...
    **{f'wgse1d_{w}_l5': dict(type='WGSE', dim=1, wavelet=w, level=5)
       for w in ('db1', 'db4', 'sym4', 'coif2')},
    # ... and db8 at 1 to 4 levels (grid_full.py crosses all of them)
    **{f'wgse1d_db8_l{n}': dict(type='WGSE', dim=1, wavelet='db8', level=n)
       for n in (1, 2, 3, 4)},
)

# the data and schedule of every run (--cfg-options of tools/train.py):
# the embedded dataset's T=41 and 128x256 frames, 64x128 training crops
cfg_options = dict(num_steps=41, crop_size='64,128')
epochs = 10  # --epochs overrides; warm-up: a tenth of them, at least one
seeds = [0, 1, 2]  # --seeds overrides
# ms per image: batch-1 inference on a validation-sized stream (median of
# `repeat` timed calls after `warmup` untimed ones)
latency = dict(repeat=5, warmup=1)
