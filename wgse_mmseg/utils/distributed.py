"""Launching distributed runs, on GPUs as in MMSeg and on CPUs with gloo.

With ``--launcher pytorch`` (``tools/dist_train.sh``, or ``torchrun ...
tools/train.py CONFIG --launcher pytorch``) mmengine's runner starts the
process group itself, for GPUs: ``init_dist`` calls
``torch.cuda.set_device`` whatever the backend. On a machine without CUDA
:func:`prepare_launcher` starts it with gloo instead, before the runner,
and wraps the model in :class:`~wgse_mmseg.engine.CPUDistributedDataParallel`
(gradients averaged across processes, as on GPUs). That is the documented
way to try a multi-process run without GPUs; it trains as slowly as CPUs do.
The wrapper is named here by its registered type; the layer's set-up
(:func:`wgse_mmseg.register_all_modules`, which the tools make before they
read a config) registers it, so this module imports nothing of the layer
above it (``engine``).
"""
import os
import warnings

import torch
import torch.distributed as dist
from mmengine.config import Config

__all__ = []


def prepare_launcher(cfg: Config) -> None:
    """Make ``cfg`` (with ``cfg.launcher`` set) runnable on this machine.

    Where CUDA is available, or the launcher is ``'none'``, nothing changes.
    Otherwise, for ``'pytorch'``: the gloo process group is initialised from
    torchrun's environment (``RANK``, ``WORLD_SIZE``, ``MASTER_ADDR``,
    ``MASTER_PORT``), ``cfg.env_cfg.dist_cfg.backend`` becomes ``'gloo'``,
    the model wrapper becomes ``CPUDistributedDataParallel`` and
    ``cfg.sync_bn`` is dropped (SyncBN needs GPUs). Other launchers raise a
    ``ValueError`` (slurm and mpi runs need GPUs here).
    """
    launcher = cfg.get('launcher', 'none')
    if launcher == 'none' or torch.cuda.is_available():
        return
    if launcher != 'pytorch':
        raise ValueError(
            f'--launcher {launcher} needs GPUs; without CUDA only '
            f"'pytorch' (torchrun, gloo) runs distributed")
    missing = [name for name in ('RANK', 'WORLD_SIZE', 'MASTER_ADDR',
                                 'MASTER_PORT') if name not in os.environ]
    if missing:
        raise ValueError(
            f'--launcher pytorch expects torchrun\'s environment; '
            f'{", ".join(missing)} not set (start with tools/dist_train.sh '
            f'or torchrun --nproc_per_node=N tools/train.py CONFIG '
            f'--launcher pytorch)')
    cfg.setdefault('env_cfg', {}).setdefault('dist_cfg', {})
    cfg.env_cfg.dist_cfg.backend = 'gloo'
    if not dist.is_initialized():
        dist.init_process_group('gloo')
    wrapper = cfg.get('model_wrapper_cfg') or {}
    cfg.model_wrapper_cfg = dict(wrapper, type='CPUDistributedDataParallel')
    if cfg.get('sync_bn'):
        if os.environ.get('RANK', '0') == '0':  # said once, not per process
            warnings.warn(f'sync_bn={cfg.sync_bn!r} ignored: SyncBN needs '
                          f'GPUs, this CPU run keeps per-process BN '
                          f'statistics')
        cfg.sync_bn = None


def _sync_bn_fields(node, path: str, found: list) -> None:
    """Append ``(path, dict)`` of every ``type='SyncBN'`` dict under
    ``node`` (dicts, lists and tuples, at any depth)."""
    if isinstance(node, dict):
        if node.get('type') == 'SyncBN':
            found.append((path, node))
        for key, value in node.items():
            _sync_bn_fields(value, f'{path}.{key}', found)
    elif isinstance(node, (list, tuple)):
        for index, value in enumerate(node):
            _sync_bn_fields(value, f'{path}[{index}]', found)


def fit_to_cpus(cfg: Config) -> None:
    """Make a model config that names SyncBN runnable where there is no
    CUDA: every ``norm_cfg`` of ``type='SyncBN'`` in ``cfg.model``, at any
    depth, becomes ``'BN'`` (per-process statistics, as one GPU has), with
    one warning naming the fields; nothing changes where CUDA is
    available. :class:`~wgse_mmseg.engine.SpikeRunner` calls it for every
    run, distributed or not."""
    if torch.cuda.is_available():
        return
    found: list = []
    _sync_bn_fields(cfg.get('model'), 'model', found)
    for _, norm in found:
        norm['type'] = 'BN'
    if found and os.environ.get('RANK', '0') == '0':
        named = ', '.join(path for path, _ in found[:4])
        warnings.warn(
            f'SyncBN needs GPUs: on this CPU machine {len(found)} norm '
            f'layers of type SyncBN are BN ({named}'
            f'{", ..." if len(found) > 4 else ""})')


def fit_workers(cfg: Config) -> None:
    """``persistent_workers`` off in every data loader of ``cfg`` that has
    ``num_workers=0`` (torch refuses the pair; ``num_workers=0``, the
    usual way to debug a pipeline, then works alone)."""
    for split in ('train', 'val', 'test'):
        loader = cfg.get(f'{split}_dataloader')
        if isinstance(loader, dict) and loader.get('num_workers') == 0 \
                and loader.get('persistent_workers'):
            loader['persistent_workers'] = False
