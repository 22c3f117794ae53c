# The paper's model trained on a REDS-layout training folder (random crops of
# crop_size with flips) instead of simulated images, validated on data_root:
#   python tools/train.py configs/reconstruction/wgse_resnet_reds.py \
#       --cfg-options train_dataloader.dataset.data_root=REDS_TRAIN \
#       data_root=REDS_VAL
_base_ = ['./wgse_resnet.py']
train_dataloader = dict(
    dataset=dict(
        _delete_=True,
        type='REDSSpikeDataset',
        data_root='data/reds_train',
        data_prefix=dict(spike_path='spike', gt_path='gt'),
        pipeline=[
            dict(type='LoadSpikeImagePair', num_steps={{_base_.num_steps}}),
            dict(type='SpikeRandomCrop', crop_size={{_base_.crop_size}}),
            dict(type='SpikeRandomFlip', prob=0.5,
                 direction=('horizontal', 'vertical')),
            dict(type='PackReconstructionInputs'),
        ]))
val_dataloader = {{_base_.test_dataloader}}
