"""Seeds: the one range, the one check and the one derivation rule.

A seed is an integer in ``0 ..`` :data:`~wgse_mmseg.limits.MAX_SEED` (63 bits,
which NumPy and torch both accept); :func:`check_seed` checks it, for the
public entry points and everywhere else.

Every seed the package makes from another is :func:`derive_seed`'s: the
parent seed and a tuple of keys (a sample's name or index, a random
stream's name) go into NumPy's ``SeedSequence`` as entropy (a string key as
the 64-bit BLAKE2b digest of its UTF-8 bytes, read little-endian, an integer
key as itself), whose first 64-bit word, cut to the seed range, is the child
seed. A 64-bit digest makes two distinct names share a stream with odds of
about ``n**2 / 2**65`` among ``n`` names (a 32-bit checksum already gives
one such pair in 100 000 names). It is stable across runs, platforms and
Python versions (no ``hash()``), distinct keys give unrelated seeds, and
:func:`derive_generator` gives the NumPy generator seeded by the same
entropy, so ``derive_generator(seed, i)`` is ``default_rng([seed, i])``.
Where a seed is to be random rather than derived, :func:`draw_seed` draws
one over the whole range.

Users: the simulator's effects (``derive_seed(clip_seed, effect_name)``),
the Spike-Cityscapes converter (``derive_seed(base_seed, stem)``), the
synthetic scenes and the simulated REDS-style views
(``derive_generator(seed, index)`` for the scene,
``derive_seed(seed, index, 'spikes')`` for its spikes) and
``SimulateSpikes`` (``derive_seed(seed, img_path)``, or :func:`draw_seed`).
"""
import hashlib
from typing import Any, List, Optional, Union

import numpy as np

from ..argument_checks import check_integer
from ..limits import MAX_SEED

__all__ = []

#: a key of a derived seed
_Key = Union[str, int]


def check_seed(value: Any, name: str = 'seed', entry: str = 'seed',
               allow_none: bool = False) -> Optional[int]:
    """``value`` as an ``int`` seed in ``0 ..`` :data:`MAX_SEED` (or
    ``None`` where allowed); else an error naming ``entry`` and ``name``."""
    if value is None and allow_none:
        return None
    return int(check_integer(entry, name, value, 0, MAX_SEED))


def _string_key_word(key: str) -> int:
    """The entropy word of a string key: the 64-bit BLAKE2b digest of its
    UTF-8 bytes as a little-endian integer (stable everywhere)."""
    digest = hashlib.blake2b(key.encode(), digest_size=8).digest()
    return int.from_bytes(digest, 'little')


def _entropy(seed: int, keys: tuple) -> List[int]:
    entropy = [check_seed(seed)]
    for key in keys:
        if isinstance(key, str):
            entropy.append(_string_key_word(key))
        else:
            entropy.append(check_seed(key, 'key', 'derive_seed'))
    return entropy


def derive_seed(seed: int, key: _Key, *keys: _Key) -> int:
    """The seed of the stream ``(key, *keys)`` of what ``seed`` seeds, in
    ``0 ..`` :data:`MAX_SEED`.

    A use gives a fixed number of keys: ``SeedSequence`` pads its entropy
    with zeros, so a last key ``0`` is the same stream as no last key.
    """
    sequence = np.random.SeedSequence(_entropy(seed, (key, ) + keys))
    return int(sequence.generate_state(1, np.uint64)[0]) & MAX_SEED


def derive_generator(seed: int, key: _Key,
                     *keys: _Key) -> np.random.Generator:
    """A NumPy generator for the stream ``(key, *keys)`` of what ``seed``
    seeds (``np.random.default_rng([seed, key, *keys])`` for integer
    keys)."""
    return np.random.default_rng(
        np.random.SeedSequence(_entropy(seed, (key, ) + keys)))


def draw_seed(rng: Optional[np.random.Generator] = None) -> int:
    """A random seed in ``0 ..`` :data:`MAX_SEED`, from ``rng`` or, when
    ``None``, from NumPy's global generator (which mmengine seeds per data
    loader worker)."""
    if rng is None:
        return int(np.random.randint(0, MAX_SEED, dtype=np.int64))
    return int(rng.integers(0, MAX_SEED, endpoint=True))
