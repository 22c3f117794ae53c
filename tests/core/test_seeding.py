"""The one seeding rule (wgse_mmseg.core.seeding): range, check, derivation,
and the places that use it."""
import os
import subprocess
import sys
import hashlib

import numpy as np
import pytest
import torch
from hypothesis import given, settings, strategies as st

from wgse_mmseg.argument_checks import ArgumentError
from wgse_mmseg.limits import MAX_SEED
from wgse_mmseg.core.seeding import (_string_key_word, check_seed,
                                     derive_generator, derive_seed,
                                     draw_seed)
from wgse_mmseg.core.simulation import simulate_spikes
from wgse_mmseg.core.simulation.effect import SimulationContext

SEEDS = st.integers(0, MAX_SEED)
KEYS = st.lists(st.one_of(st.text(max_size=20), st.integers(0, MAX_SEED)),
                min_size=1, max_size=3)


@settings(max_examples=200, deadline=None)
@given(seed=SEEDS, keys=KEYS)
def test_derived_seeds_lie_in_the_one_range_and_are_accepted(seed, keys):
    child = derive_seed(seed, *keys)
    assert type(child) is int and 0 <= child <= MAX_SEED
    assert check_seed(child) == child
    torch.Generator().manual_seed(child)  # both libraries take it
    np.random.default_rng(child)


@settings(max_examples=100, deadline=None)
@given(seed=SEEDS, key=st.text(max_size=20))
def test_a_string_key_enters_as_its_64_bit_blake2b(seed, key):
    """The documented rule, computed here from hashlib and NumPy's
    SeedSequence."""
    digest = hashlib.blake2b(key.encode(), digest_size=8).digest()
    word = np.random.SeedSequence(
        [seed, int.from_bytes(digest, 'little')]).generate_state(
            2, np.uint32)
    expected = (int(word[0]) | int(word[1]) << 32) & (2**63 - 1)
    assert derive_seed(seed, key) == expected


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**40), index=st.integers(0, 10**6))
def test_derived_generator_is_default_rng_of_the_seed_and_keys(seed, index):
    ours = derive_generator(seed, index).integers(0, 2**62, 8)
    assert np.array_equal(ours,
                          np.random.default_rng([seed, index]).integers(
                              0, 2**62, 8))


def test_keys_separate_streams():
    seeds = {derive_seed(0, 'a'), derive_seed(0, 'b'), derive_seed(1, 'a'),
             derive_seed(0, 'a', 'spikes'), derive_seed(0, 0),
             derive_seed(0, 1), derive_seed(0, 1, 1)}
    assert len(seeds) == 7
    assert derive_seed(5, 'x', 3) == derive_seed(5, 'x', 3)


def test_distinct_names_give_distinct_seeds_over_a_million_names():
    """The promise "distinct keys give unrelated seeds" where it can fail:
    a million short names (a 32-bit checksum gives about a hundred
    colliding pairs among them) keep a million distinct string words, and
    names that a 32-bit checksum maps together get different seeds."""
    names = [f'data/{i:07d}.png' for i in range(10**6)]
    words = {_string_key_word(name) for name in names}
    assert len(words) == len(names)
    sample = names[::100]
    assert len({derive_seed(3, n) for n in sample}) == len(sample)
    assert derive_seed(0, 'data/plumless.png') != derive_seed(
        0, 'data/buckeroo.png')


def test_derivation_does_not_depend_on_the_interpreter():
    """No hash(): another process with another hash seed agrees (one
    process is enough: its hash seed differs from this one's)."""
    code = ('from wgse_mmseg.core.seeding import derive_seed;'
            'print(derive_seed(7, "aachen_000000_000019", 3))')
    hash_seed = '2' if os.environ.get('PYTHONHASHSEED') == '1' else '1'
    out = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True,
        check=True, env={**os.environ, 'PYTHONHASHSEED': hash_seed})
    assert int(out.stdout) == derive_seed(7, 'aachen_000000_000019', 3)


@pytest.mark.parametrize('value', [-1, MAX_SEED + 1, 2.0, '3', True, None])
def test_check_refuses_what_is_no_seed_naming_the_field(value):
    with pytest.raises(ArgumentError, match=r'sensor\.sensor_seed'):
        check_seed(value, 'sensor.sensor_seed', 'effects')


def test_check_allows_none_where_asked():
    assert check_seed(None, allow_none=True) is None
    assert check_seed(np.int64(4)) == 4


@pytest.mark.parametrize('bad', [-1, MAX_SEED + 1, 1.5])
def test_derivation_refuses_a_bad_seed_or_key(bad):
    with pytest.raises(ArgumentError):
        derive_seed(bad, 'key')
    with pytest.raises(ArgumentError):
        derive_seed(0, bad)


def test_draws_cover_the_range_and_follow_their_generator():
    draws = [draw_seed(np.random.default_rng(i)) for i in range(64)]
    assert all(0 <= d <= MAX_SEED for d in draws)
    assert max(draws) > 2**62  # the whole 63-bit range, not 31 bits
    np.random.seed(3)
    first = draw_seed()
    np.random.seed(3)
    assert draw_seed() == first and 0 <= first <= MAX_SEED


def test_an_effect_generator_is_seeded_by_the_rule():
    context = SimulationContext(2, 3, 1, 4, 1.0, 1.0, 40000.0, 11,
                                torch.device('cpu'))
    ours = context.generator('shot_noise')
    reference = torch.Generator().manual_seed(derive_seed(11, 'shot_noise'))
    assert torch.equal(torch.rand(5, generator=ours),
                       torch.rand(5, generator=reference))
    sensor = context.generator('fixed_pattern', seed=2)
    reference = torch.Generator().manual_seed(derive_seed(2, 'fixed_pattern'))
    assert torch.equal(torch.rand(5, generator=sensor),
                       torch.rand(5, generator=reference))


def test_simulator_accepts_every_derived_seed():
    frames = np.full((1, 4, 8), 0.5)
    for key in ('a', 'b', 'c'):
        seed = derive_seed(MAX_SEED, key)
        spikes, meta = simulate_spikes(frames, 6, seed=seed,
                                       effects=dict(shot_noise={}))
        assert meta['seed'] == seed and spikes.shape == (6, 4, 8)
