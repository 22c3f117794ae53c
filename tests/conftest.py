"""Shared test configuration for wgse_mmseg."""
import os.path as osp

import pytest
import torch
from hypothesis import settings

settings.register_profile('ci', deadline=None, max_examples=40)
settings.load_profile('ci')

REPO_ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))


@pytest.fixture(scope='session')
def shared_dir():
    """``../shared`` beside the repository root; skips when it is absent."""
    path = osp.normpath(osp.join(REPO_ROOT, '..', 'shared'))
    if not osp.isdir(path):
        pytest.skip(f'shared data directory {path} is absent (fresh clone)')
    return path


@pytest.fixture(scope='module')
def single_thread():
    """Tiny tensors only: one intra-op thread avoids OpenMP oversubscription,
    which on a busy 2-core machine made these tests ~50x slower."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
