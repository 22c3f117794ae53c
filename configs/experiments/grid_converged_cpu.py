# Does WGSE beat the representations it claims to improve? The comparison
# at a schedule where the training losses have flattened, with the
# ablations of the WGSE-versus-TFP gap, sized for a 2-core CPU
# (docs/wgse_vs_tfp.md has the findings and the commands, docs/converged/
# and docs/converged_720/ the reports; tools/analysis_tools/run_experiments.py
# runs it).
#
# Data: the embedded street scenes made at 64x128 with more samples than the
# default (192 training, 32 validation streams, T=41):
#   python tools/dataset_converters/make_synthetic_dataset.py \
#       data/spike_streets_64x128 --height 64 --width 128 \
#       --num-train 192 --num-val 32
# Training: 32x64 crops, batch 4, 240 iterations (--max-iters 240, five
# epochs); validation on the whole 64x128 frames.

# PSPNet with a ResNet-18 backbone and head widths as MMSeg's pspnet_r18-d8
# configs (the R50 model did not fit a 2-core CPU's budget for this grid);
# SegFormer-B0 as shipped
models = dict(
    segformer_b0='configs/segformer_b0_raw.py',
    pspnet_r18=dict(
        config='configs/pspnet_raw.py',
        cfg_options={
            'model.backbone.depth': 18,
            'model.decode_head.in_channels': 512,
            'model.decode_head.channels': 128,
            'model.auxiliary_head.in_channels': 256,
            'model.auxiliary_head.channels': 64,
        }),
)

# enhancer name -> `model.data_preprocessor.enhancer`, or
# dict(enhancer=..., cfg_options=...) for a variant that also changes the
# training recipe
enhancers = dict(
    raw=None,
    tfp=dict(type='TFP', window=21),  # about half the stream
    tfi=dict(type='TFI'),
    mean_spatial=dict(type='SpatialMeanFilter', kernel_size=3),
    mean_temporal=dict(type='TemporalMeanFilter', kernel_size=3),
    # WGSE as in the paper (db8, 5 levels) and the paper's variants
    wgse1d=dict(type='WGSE', dim=1),
    wgse2d=dict(type='WGSE', dim=2),
    wgse3d=dict(type='WGSE', dim=3),
    wgse1d_long=dict(type='WGSE', dim=1, num_blocks=2),
    trcnn=dict(type='WGSE', dim=1, wavelet=None),
    # ablations of the gap to TFP: the enhancer's learning rate (10x the
    # model's), an initialisation that starts at the level-5 approximation
    # (a window average about as long as TFP's), a normalised output, and
    # narrower band networks (which also cut its FLOPs)
    wgse1d_lr10=dict(
        enhancer=dict(type='WGSE', dim=1),
        cfg_options={
            'optim_wrapper.paramwise_cfg.custom_keys.enhancer.lr_mult': 10
        }),
    wgse1d_lowpass_init=dict(type='WGSE', dim=1, init='lowpass'),
    wgse1d_norm=dict(type='WGSE', dim=1, output_norm=True),
    wgse1d_w16=dict(type='WGSE', dim=1, hidden_channels=16),
    wgse1d_w8=dict(type='WGSE', dim=1, hidden_channels=8),
)

cfg_options = dict(num_steps=41, crop_size='32,64')
epochs = 5  # the runs use --max-iters 240 (the same length)
seeds = [0, 1, 2]
latency = dict(repeat=5, warmup=1)
