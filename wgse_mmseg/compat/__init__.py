"""Adapters between the pinned OpenMMLab stack and this machine's torch/mmcv."""
from .checkpoint_safety import allow_mmengine_checkpoints
from .mmcv_ops_fallback import install_mmcv_ops_fallback

__all__ = ['allow_mmengine_checkpoints', 'install_mmcv_ops_fallback']
