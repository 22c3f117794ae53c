"""Distributed data parallel on CPUs, for trying multi-process runs without
GPUs (``--launcher pytorch`` with the gloo backend).

mmengine's runner gives every ``DistributedDataParallel`` wrapper
``device_ids=[LOCAL_RANK]``, which torch accepts only for a model on a GPU;
this wrapper drops them for a model on the CPU and is otherwise
:class:`~mmengine.model.MMDistributedDataParallel`.
:func:`wgse_mmseg.utils.distributed.prepare_launcher` selects it.
"""
from typing import List, Optional

import torch.nn as nn
from mmengine.model import MMDistributedDataParallel
# mmengine's root registry: the runner looks wrappers up there by name
from mmengine.registry import MODEL_WRAPPERS

__all__ = ['CPUDistributedDataParallel']


@MODEL_WRAPPERS.register_module()
class CPUDistributedDataParallel(MMDistributedDataParallel):
    """:class:`MMDistributedDataParallel` for a model whose parameters are on
    the CPU: ``device_ids`` are ignored (torch requires ``None`` there)."""

    def __init__(self, module: nn.Module,
                 device_ids: Optional[List[int]] = None, **kwargs):
        devices = {p.device.type for p in module.parameters()}
        if devices != {'cpu'}:
            raise ValueError(
                f'CPUDistributedDataParallel wraps a model on the CPU; its '
                f'parameters are on {sorted(devices)}')
        super().__init__(module=module, device_ids=None, **kwargs)
