"""The one timer of every benchmark: wall and CPU seconds of repeated calls,
and their summary (median and median absolute deviation)."""
import statistics
import time
from typing import (TYPE_CHECKING, Any, Callable, Dict, List, NamedTuple,
                    Sequence, Union)

from wgse_mmseg.argument_checks import check_integer
from wgse_mmseg.limits import MAX_REPEAT

if TYPE_CHECKING:  # torch where a call is timed (a tool's --help needs none)
    import torch

__all__ = ['time_calls']


class Timings(NamedTuple):
    """What :func:`time_calls` measured, one entry per timed call."""
    wall: List[float]  # wall seconds
    cpu: List[float]  # CPU seconds of this process (all its threads)
    result: Any  # the last call's return value


def _synchronize(device: 'torch.device') -> None:
    import torch
    if device.type == 'cuda':
        torch.cuda.synchronize(device)


def check_repeats(entry: str, repeat: int, warmup: int) -> None:
    """``entry``'s ``repeat`` (timed calls, >= 1) and ``warmup`` (untimed
    ones first, >= 0), each at most :data:`MAX_REPEAT`."""
    check_integer(entry, 'repeat', repeat, 1, MAX_REPEAT)
    check_integer(entry, 'warmup', warmup, 0, MAX_REPEAT)


def time_calls(fn: Callable[[], Any], device: Union[str, 'torch.device'],
               repeat: int, warmup: int) -> Timings:
    """Seconds taken by each of ``repeat`` calls of ``fn`` after ``warmup``
    untimed ones; on CUDA the device is synchronised before and after each
    timed call, so a call's queued kernels count as its own.

    The CPU time is the steadier figure on a machine shared with other
    work; on an idle one, with one thread, the two agree.
    """
    from wgse_mmseg.core.checks import check_device
    check_repeats('time_calls', repeat, warmup)
    if not callable(fn):
        raise TypeError(f'time_calls: fn must be callable, got {fn!r}')
    device = check_device('time_calls', 'device', device)
    result = None
    for _ in range(warmup):
        result = fn()
    walls, cpus = [], []
    for _ in range(repeat):
        _synchronize(device)
        wall, cpu = time.perf_counter(), time.process_time()
        result = fn()
        _synchronize(device)
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return Timings(walls, cpus, result)


def summarize(samples: Sequence[float]) -> Dict[str, Any]:
    """``{'median', 'mad', 'samples'}`` of ``samples`` (same unit)."""
    if not samples:
        raise ValueError('no samples to summarize (repeat must be >= 1)')
    median = statistics.median(samples)
    mad = statistics.median(abs(s - median) for s in samples)
    return dict(median=median, mad=mad, samples=list(samples))
