"""Independent pieces of CPU work, one piece per torch thread.

torch splits every operation over its intra-op threads. For many small
operations on independent pieces (chunks of pixels, tiles of a frame) that
split costs more than it gains: at 16,384 pixels and a few dozen steps per
operation two threads ran the spike simulator 3.5x slower than one. Running
whole pieces side by side, each on one torch thread, uses the cores instead.
"""
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, List, TypeVar

import torch

__all__ = []

_State = TypeVar('_State')


def for_each_on_threads(task: Callable[[int, _State], None], count: int,
                        make_state: Callable[[], _State]) -> List[_State]:
    """Run ``task(item, state)`` for items ``0 .. count-1``.

    Every task runs on one torch thread, so an item's arithmetic does not
    depend on the thread count. With ``n = torch.get_num_threads() > 1``
    (and more than one item) the
    items run on ``n`` threads; thread ``i``
    takes items ``i, i + n, ...`` with its own ``state`` (buffers, partial
    sums), so what a state accumulates does not depend on timing. Tasks run
    without autograd (grad mode is per thread; set it off here too) and
    must write disjoint outputs. torch's thread count is restored, and the
    first error raised by a task is re-raised.

    Returns:
        The states, thread by thread (one when run in this thread).
    """
    torch_threads = torch.get_num_threads()
    threads = max(1, min(torch_threads, count))
    states = [make_state() for _ in range(threads)]
    if threads == 1:
        try:  # one torch thread whatever the count: the same arithmetic
            torch.set_num_threads(1)
            for item in range(count):
                task(item, states[0])
        finally:
            torch.set_num_threads(torch_threads)
        return states

    def worker(first: int) -> None:
        torch.set_num_threads(1)
        with torch.no_grad():
            for item in range(first, count, threads):
                task(item, states[first])

    try:
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(worker, range(threads)))
    finally:
        torch.set_num_threads(torch_threads)
    return states
