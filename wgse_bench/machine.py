"""What machine and software a measurement ran on, and a fresh process to
run it in: the one machine record of every benchmark table."""
import concurrent.futures
import multiprocessing
import os
import platform
import shutil
import subprocess
import sys
from importlib import metadata
from typing import Any, Callable, Dict

import torch

__all__ = []

#: record key -> the distributions whose version it states, the first
#: installed of them (``'not installed'`` where none is)
PACKAGES = {
    'numpy': ('numpy', ),
    'opencv': ('opencv-python', 'opencv-python-headless'),
    'pywavelets': ('PyWavelets', ),
    'triton': ('triton', ),
    'pytorch_wavelets': ('pytorch_wavelets', ),
    'mmcv': ('mmcv', 'mmcv-lite'),
    'mmengine': ('mmengine', ),
    'mmsegmentation': ('mmsegmentation', ),
    'wgse_mmseg': ('wgse_mmseg', ),
}


def _cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what platform says."""
    try:
        with open('/proc/cpuinfo') as f:
            for line in f:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _package_version(name: str, *alternatives: str) -> str:
    """Version of distribution ``name``, or of the first installed
    alternative (named then, e.g. ``2.1.0 (mmcv-lite)``)."""
    for candidate in (name, ) + alternatives:
        try:
            version = metadata.version(candidate)
        except metadata.PackageNotFoundError:
            continue
        return version if candidate == name else f'{version} ({candidate})'
    return 'not installed'


def _driver() -> str:
    smi = shutil.which('nvidia-smi')
    if smi is None:
        return 'unknown (no nvidia-smi)'
    proc = subprocess.run([smi, '--query-gpu=driver_version',
                           '--format=csv,noheader'], capture_output=True,
                          text=True)
    return proc.stdout.strip().splitlines()[0] if proc.returncode == 0 and \
        proc.stdout.strip() else f'unknown (nvidia-smi: {proc.stderr.strip()})'


def machine_record(device: str = 'cpu') -> Dict[str, Any]:
    """The device, CPU, load and software versions of a measurement on
    ``device`` (``'cpu'``, ``'cuda'``, ``'cuda:N'``), JSON-ready.

    Keys: ``device``, ``cpu``, ``cpu_count`` (logical CPUs),
    ``torch_threads``, ``load_average`` (1 minute, ``None`` where the OS
    has none), ``python``, ``platform``, ``torch`` and each key of
    :data:`PACKAGES`; on CUDA also ``gpu``, ``capability``,
    ``gpu_memory_gib``, ``sms``, ``sm_clock_mhz`` (the SMs' peak clock the
    driver reports; ``None`` where torch does not read it), ``driver``,
    ``cuda`` and ``cudnn``. Reads
    versions from the installed distributions' metadata: imports nothing of
    OpenMMLab.
    """
    record = dict(
        device=device, cpu=_cpu_model(), cpu_count=os.cpu_count(),
        torch_threads=torch.get_num_threads(),
        load_average=os.getloadavg()[0] if hasattr(os, 'getloadavg')
        else None,
        python=platform.python_version(), platform=platform.platform(),
        torch=torch.__version__)
    for key, names in PACKAGES.items():
        record[key] = _package_version(*names)
    if device.startswith('cuda'):
        props = torch.cuda.get_device_properties(torch.device(device))
        record.update(gpu=props.name,
                      capability=f'sm_{props.major}{props.minor}',
                      gpu_memory_gib=round(props.total_memory / 2**30, 1),
                      sms=props.multi_processor_count,
                      sm_clock_mhz=getattr(props, 'clock_rate', 0) / 1e3
                      or None, driver=_driver(),
                      cuda=torch.version.cuda,
                      cudnn=torch.backends.cudnn.version())
    return record


def _set_up_like_the_parent(mmseg_layer: bool) -> None:
    """A fresh worker's first step: the MMSeg layer's explicit set-up where
    the parent process had made it (a function of the layer cannot even be
    unpickled before it, under mmcv-lite)."""
    if mmseg_layer:
        from wgse_mmseg import register_all_modules
        register_all_modules()


def run_isolated(fn: Callable, *args, **kwargs):
    """``fn(*args, **kwargs)`` in a fresh (spawned) process, so that memory
    and allocator state of earlier work do not leak into measurements. The
    process sets the MMSeg layer up first where this one has."""
    context = multiprocessing.get_context('spawn')
    layer = 'wgse_mmseg.models' in sys.modules
    with concurrent.futures.ProcessPoolExecutor(
            1, mp_context=context, initializer=_set_up_like_the_parent,
            initargs=(layer, )) as pool:
        return pool.submit(fn, *args, **kwargs).result()
