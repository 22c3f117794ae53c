"""The Spike-Cityscapes converter's command line, SIGKILLed at a chosen
file-system step: what each child process of
``test_cityscapes_conversion.py::test_converter_survives_sigkill`` runs.

The children are forked by multiprocessing's fork server, a fresh
single-threaded interpreter that has imported the converter's modules once:
each kill costs a fork, not a start of Python and torch. No child is forked
from the test process itself, whose other threads (pytest-xdist's, a
progress bar's monitor, pytest-timeout's) may hold a lock at the moment of
the fork that the child then waits for forever or finds corrupt (seen: a
child hanging until CI's time ran out, and one segfaulting in the garbage
collector)."""
import os
import os.path as osp
import runpy
import signal
import sys

import torch

CONVERTER = osp.join(osp.dirname(osp.dirname(osp.dirname(
    osp.abspath(__file__)))), 'tools', 'dataset_converters',
    'spike_cityscapes.py')


def run_killed_at(step: int, when: str, args) -> None:
    """Run the converter with command-line ``args``, killing this process
    with SIGKILL just ``when`` (``'before'`` or ``'after'``) its
    ``step``-th file-system step (1-based; every ``os.replace``, an atomic
    write landing, and every ``os.remove``): before a replace, the
    temporary file is written but not in place, as when the kill lands
    mid-write. The converter's ``SystemExit`` is the process's exit code."""
    torch.set_num_threads(1)
    count = 0

    def counted(function):
        def wrapper(*a, **k):
            nonlocal count
            count += 1
            if count == step and when == 'before':
                os.kill(os.getpid(), signal.SIGKILL)
            result = function(*a, **k)
            if count == step and when == 'after':
                os.kill(os.getpid(), signal.SIGKILL)
            return result
        return wrapper

    os.replace, os.remove = counted(os.replace), counted(os.remove)
    sys.argv = [CONVERTER, *args]
    runpy.run_path(CONVERTER, run_name='__main__')
