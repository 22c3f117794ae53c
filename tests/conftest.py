"""Shared test configuration for wgse_mmseg."""
import os
import os.path as osp

# Triton kernels run in triton's CPU interpreter here (CI has no GPU); it is
# chosen when a kernel is defined, so before anything imports triton.
os.environ.setdefault('TRITON_INTERPRET', '1')

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402
from hypothesis import settings  # noqa: E402

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


@pytest.fixture(scope='session', autouse=True)
def interpreter_bfloat16_dot():
    """triton 3.6's interpreter multiplies bfloat16 ``tl.dot`` operands as
    their raw 16-bit storage (``create_dot`` converts only 8-bit floats),
    which gives garbage; widen them to float32 first, exactly (a bfloat16 is
    the top half of a float32), so the kernels' bf16 path can be tested."""
    try:
        from triton.runtime import interpreter
        import triton.language as tl
    except ImportError:
        yield
        return
    original = interpreter.InterpreterBuilder.create_dot

    def widen(handle):
        if handle.dtype.scalar == tl.bfloat16:
            data = (handle.data.astype(np.uint32) << 16).view(np.float32)
            return interpreter.TensorHandle(data, tl.float32)
        return handle

    def create_dot(self, a, b, d, *args):
        return original(self, widen(a), widen(b), d, *args)

    interpreter.InterpreterBuilder.create_dot = create_dot
    yield
    interpreter.InterpreterBuilder.create_dot = original
