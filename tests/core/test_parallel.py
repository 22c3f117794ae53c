import pytest
import torch

from wgse_mmseg.core.parallel import for_each_on_threads
from wgse_mmseg.core.simulation import simulate_spikes


@pytest.fixture
def threads():
    """Set torch's thread count for one test, restored afterwards."""
    before = torch.get_num_threads()
    yield torch.set_num_threads
    torch.set_num_threads(before)


@pytest.mark.parametrize('num_threads,count', [(1, 5), (2, 7), (3, 2)])
def test_items_split_round_robin_and_thread_count_restored(
        threads, num_threads, count):
    threads(num_threads)
    seen = for_each_on_threads(
        lambda item, state: state.append(
            (item, torch.get_num_threads(), torch.is_grad_enabled())),
        count, list)
    used = min(num_threads, count)
    assert len(seen) == used
    for first, state in enumerate(seen):
        assert [item for item, _, _ in state] == list(
            range(first, count, used))
        inner = 1 if used > 1 else num_threads
        assert all(t == inner for _, t, _ in state)
        if used > 1:  # tasks on worker threads run without autograd
            assert not any(grad for _, _, grad in state)
    assert torch.get_num_threads() == num_threads


def test_error_in_a_task_is_raised_and_threads_restored(threads):
    threads(2)

    def task(item, state):
        if item == 3:
            raise ValueError('item 3')

    with pytest.raises(ValueError, match='item 3'):
        for_each_on_threads(task, 6, list)
    assert torch.get_num_threads() == 2


def test_no_items():
    assert for_each_on_threads(lambda item, state: None, 0, list) == [[]]


def test_simulator_same_spikes_on_one_and_two_threads(threads):
    frames = torch.rand(3, 40, 70, generator=torch.Generator().manual_seed(0))
    # tiles of 16384 pixels: 40x70 is one tile, so stack a wider one
    wide = frames.repeat(1, 1, 8).numpy()
    results = []
    for num_threads in (1, 2):
        threads(num_threads)
        for effects in (None, {'shot_noise': {}}):
            results.append(simulate_spikes(wide, 41, effects=effects,
                                           seed=5)[0])
    for single, double in zip(results[:2], results[2:]):
        assert (single == double).all()
