"""Shards: a disjoint part of a job's samples, so that machines share it.

Shard ``K/N`` holds the samples whose position in the job's deterministic
order (sorted by name) is ``K - 1`` modulo ``N``. The ``N`` shards of one
job are disjoint and together hold every sample, so ``N`` processes, on one
machine or many (a Slurm array: ``tools/slurm_convert.sh``), each given one
shard of the same job, make exactly what one process makes alone.
"""
from typing import List, NamedTuple, Sequence, TypeVar

from ..command_line import Argument
from ..limits import MAX_SAMPLES

__all__ = []

_Item = TypeVar('_Item')


class Shard(NamedTuple):
    """Part ``index`` (1-based) of ``count`` parts of a job."""
    index: int
    count: int

    def select(self, items: Sequence[_Item]) -> List[_Item]:
        """This shard's ``items``: positions ``index - 1``,
        ``index - 1 + count``, ... of ``items``, in order."""
        return list(items)[self.index - 1::self.count]

    def __str__(self):
        return f'{self.index}/{self.count}'


class ShardArgument(Argument):
    """A :class:`Shard` (or pair) ``(K, N)`` of ints with
    ``1 <= K <= N <=`` :data:`~wgse_mmseg.limits.MAX_SAMPLES`; on a
    command line, the word ``K/N``."""

    def accepts(self, value):
        return (isinstance(value, tuple) and len(value) == 2
                and all(isinstance(v, int) and not isinstance(v, bool)
                        for v in value)
                and 1 <= value[0] <= value[1] <= MAX_SAMPLES)

    def describe(self):
        return f'K/N with 1 <= K <= N <= {MAX_SAMPLES}'

    def convert(self, text):
        index, count = text.split('/')
        return Shard(int(index), int(count))


#: the declaration of a shard
SHARD = ShardArgument()
#: the whole job, one shard
WHOLE = Shard(1, 1)
