"""What machine and software a measurement ran on, and a fresh process to
run it in, for the benchmark tables."""
import concurrent.futures
import multiprocessing
import platform
from importlib import metadata
from typing import Callable

__all__ = ['cpu_model', 'package_version', 'run_isolated']


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what platform says."""
    try:
        with open('/proc/cpuinfo') as f:
            for line in f:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def package_version(name: str, *alternatives: str) -> str:
    """Version of distribution ``name``, or of the first installed
    alternative (named then, e.g. ``2.1.0 (mmcv-lite)``)."""
    for candidate in (name, ) + alternatives:
        try:
            version = metadata.version(candidate)
        except metadata.PackageNotFoundError:
            continue
        return version if candidate == name else f'{version} ({candidate})'
    return 'not installed'


def run_isolated(fn: Callable, *args, **kwargs):
    """``fn(*args, **kwargs)`` in a fresh (spawned) process, so that memory
    and allocator state of earlier work do not leak into measurements."""
    context = multiprocessing.get_context('spawn')
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=context) as pool:
        return pool.submit(fn, *args, **kwargs).result()
