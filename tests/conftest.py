"""Shared test configuration for wgse_mmseg."""
import contextlib
import importlib.util
import os
import os.path as osp
import resource
import time

# Triton kernels run in triton's CPU interpreter here (CI has no GPU); it is
# chosen when a kernel is defined, so before anything imports triton.
os.environ.setdefault('TRITON_INTERPRET', '1')
# The suite runs one worker a core, each with OpenMP's threads and the tools
# it starts: a thread waiting for work sleeps instead of spinning on a core
# another worker needs (measured: 12% less CPU time for the whole suite).
# Read when torch loads the OpenMP runtime, so before it is imported; the
# tools' processes inherit it.
os.environ.setdefault('OMP_WAIT_POLICY', 'PASSIVE')
# And each worker (with the tools it starts) gets its share of the cores for
# OpenMP, one thread where there is one worker a core: two threads a worker
# on two busy cores cost more CPU than they save (measured on the 2-core
# machine: the suite's wall time 8:55 -> 7:41, its CPU time 17.2 -> 14.8
# minutes). Tests of threading set their counts themselves.
if os.environ.get('PYTEST_XDIST_WORKER_COUNT'):
    os.environ.setdefault('OMP_NUM_THREADS', str(max(1, (
        os.cpu_count() or 1) // int(os.environ['PYTEST_XDIST_WORKER_COUNT']))))

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402
from hypothesis import settings  # noqa: E402

from wgse_mmseg.openmmlab_stack import (missing_openmmlab,  # noqa: E402
                                        prepare_mmseg_layer)

# The test process sets the MMSeg layer up as every entry point does, by an
# explicit call before anything imports MMSeg (importing the package's
# modules applies no patch); where OpenMMLab is absent, core tests still run.
if not missing_openmmlab():
    prepare_mmseg_layer('the tests')

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


@pytest.fixture(scope='session')
def load_tool():
    """A function: a script's path from the repository root
    (``'tools/demo.py'``) -> the script imported as a fresh module, to call
    its ``main`` or helpers in-process."""
    def load(relative: str):
        name = 'tool_' + osp.splitext(relative)[0].replace('/', '_')
        spec = importlib.util.spec_from_file_location(
            name, osp.join(REPO_ROOT, relative))
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module
    return load


@pytest.fixture(scope='module')
def single_thread():
    """Tiny tensors only: one intra-op thread avoids OpenMP oversubscription,
    which on a busy 2-core machine made these tests ~50x slower."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


#: one entry per fork of this process (``os.fork``, multiprocessing's
#: ``fork`` start, a DataLoader's workers); a subprocess or a spawned
#: process starts without one
_FORKS = []
os.register_at_fork(before=lambda: _FORKS.append(None))


@pytest.fixture(autouse=True)
def forks_nothing():
    """No test forks the test process: its other threads (pytest-xdist's,
    pytest-timeout's, a progress bar's monitor) may hold a lock at the
    moment of the fork that the child then waits for forever (a CI run
    hung so) or finds corrupt (a child crashed so). Start a subprocess, a
    spawned process or multiprocessing's fork server instead, and load a
    training's samples in the process (``num_workers=0``)."""
    before = len(_FORKS)
    yield
    assert len(_FORKS) == before, 'the test forked the test process'


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


@pytest.fixture(scope='session', autouse=True)
def interpreter_patches_each_module_once_a_launch():
    """triton 3.6's interpreter patches ``triton.language`` for a kernel's
    module when it launches the kernel (``GridExecutor``, undone when the
    launch ends), then again, never undone, at every call of a
    ``@triton.jit`` function from inside it (``InterpretedFunction.__call__``:
    ``inspect.getmembers`` over the language's modules each time), the
    kernel's helpers and ``tl.sum`` and ``tl.zeros`` (of
    ``triton.language.standard``) alike. A repeat patches nothing new (the
    patched members are no longer builtins), so within a launch each
    module's functions are patched once: the first call as before, later
    calls run the rewritten function directly (a WGSE forward+backward at
    1x12x3x4: 1,310 patches, about a third of the interpreter's time, before
    this)."""
    try:
        from triton.runtime import interpreter
    except ImportError:
        yield
        return
    launches = []  # per launch being run: the module globals it patched
    original_launch = interpreter.GridExecutor.__call__
    original_call = interpreter.InterpretedFunction.__call__

    def launch(self, *args, **kwargs):
        launches.append({id(self.fn.__globals__)})
        try:
            return original_launch(self, *args, **kwargs)
        finally:
            launches.pop()

    def call(self, *args, **kwargs):
        module = id(self.fn.__globals__)
        if not launches or module not in launches[-1]:
            result = original_call(self, *args, **kwargs)
            if launches:
                launches[-1].add(module)
            return result
        try:
            return self.rewrite()(*args, **kwargs)
        except Exception as error:
            raise interpreter.InterpreterError(repr(error)) from error

    interpreter.GridExecutor.__call__ = launch
    interpreter.InterpretedFunction.__call__ = call
    yield
    interpreter.GridExecutor.__call__ = original_launch
    interpreter.InterpretedFunction.__call__ = original_call


@pytest.fixture(scope='session')
def built_once(tmp_path_factory):
    """``built_once(name, build) -> path``: the file ``name`` that
    ``build(path)`` writes, built once for the whole run, whichever
    pytest-xdist worker asks first (the others wait for it and share it):
    a module-scoped fixture is built once per worker, and work stealing
    spreads a module's tests over the workers. Under a lock in the run's
    base temporary directory, which the workers share."""
    from filelock import FileLock
    shared = tmp_path_factory.getbasetemp()
    if os.environ.get('PYTEST_XDIST_WORKER'):
        shared = shared.parent  # the workers' directories are in one
    shared = shared / 'built_once'
    shared.mkdir(exist_ok=True)

    def get(name: str, build):
        path = shared / name
        with FileLock(str(shared / f'{name}.lock')):
            if not path.exists():
                partial = shared / f'partial_{name}'  # its suffix kept
                partial.unlink(missing_ok=True)  # of a build that failed
                build(str(partial))
                partial.rename(path)
        return str(path)
    return get


@pytest.fixture(scope='session')
def tiny_spike_dataset(tmp_path_factory):
    """A synthetic Spike-Cityscapes-layout set for short runs of the tools:
    4 training and 1 validation sample, T=9, 32x64. Tests that change it
    work on a copy."""
    from wgse_mmseg.data_generation.synthetic import make_synthetic_dataset
    root = tmp_path_factory.mktemp('tiny_spike_dataset')
    make_synthetic_dataset(str(root), num_train=4, num_val=1, height=32,
                           width=64, num_steps=9, progress=False)
    return root


@pytest.fixture(scope='session')
def tiny_run_options():
    """``options(data, *extra, batch_size=2, workers=0)``: the
    ``--cfg-options`` of a tool run on a set like ``tiny_spike_dataset``
    (T=9, crop 32x64, a log line per iteration, ``workers`` loader workers,
    none persistent), then ``extra`` ``key=value`` settings."""

    def options(data, *extra, batch_size=2, workers=0):
        loaders = [f'{split}_dataloader.{key}={value}'
                   for split in ('train', 'val', 'test')
                   for key, value in (('num_workers', workers),
                                      ('persistent_workers', False))]
        return ['--cfg-options', f'data_root={data}', 'num_steps=9',
                'crop_size=32,64', f'train_dataloader.batch_size={batch_size}',
                'default_hooks.logger.interval=1', *loaders, *extra]

    return options


#: a ``sitecustomize`` that refuses to import OpenMMLab, as on a GPU machine
#: with torch alone
_HIDE_OPENMMLAB = '''
import importlib.abc, sys
class _HideOpenMMLab(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('mmengine', 'mmseg', 'mmcv'):
            raise ModuleNotFoundError(f'No module named {name!r} (hidden)',
                                      name=name)
sys.meta_path.insert(0, _HideOpenMMLab())
'''


@pytest.fixture
def without_openmmlab(tmp_path):
    """The environment of a subprocess (every process it starts too) in
    which mmengine, mmsegmentation and mmcv cannot be imported: a
    ``sitecustomize`` in ``tmp_path`` refuses them; the checkout first on
    the path, one thread, Triton compiled rather than interpreted."""
    (tmp_path / 'sitecustomize.py').write_text(_HIDE_OPENMMLAB)
    env = dict(os.environ, PYTHONPATH=f'{tmp_path}{os.pathsep}{REPO_ROOT}',
               OMP_NUM_THREADS='1')
    env.pop('TRITON_INTERPRET', None)
    return env


@contextlib.contextmanager
def _bounded(seconds: float, memory_bytes: int):
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    start = time.perf_counter()
    try:
        yield
    finally:  # an error the block raises counts against the bounds too
        assert time.perf_counter() - start < seconds
        grown = resource.getrusage(
            resource.RUSAGE_SELF).ru_maxrss * 1024 - peak
        assert grown < memory_bytes, f'{grown} bytes more at the peak'


@pytest.fixture
def bounded():
    """``with bounded(seconds, memory_bytes): ...``: the block must end
    within ``seconds`` and raise this process's peak memory by less than
    ``memory_bytes`` (safety bounds for fuzzed input, not timings)."""
    return _bounded


@pytest.fixture(scope='module')
def wrong_file_kinds(tmp_path_factory):
    """Paths of each wrong kind a path argument is fuzzed with:
    ``directory``, ``empty`` (an empty ``.npy``), ``text`` (quotes and a
    backslash in a ``.spk``) and ``missing``. Fresh for each test module:
    a fuzzed output argument may create ``missing`` (rightly), and a test
    of another module on the same worker then found a file there."""
    root = tmp_path_factory.mktemp('wrong_file_kinds')
    (root / 'empty.npy').write_bytes(b'')
    (root / 'text.spk').write_text('it\'s "quoted" \\ text')
    return dict(directory=str(root), empty=str(root / 'empty.npy'),
                text=str(root / 'text.spk'),
                missing=str(root / 'missing.npy'))


def pytest_runtest_setup(item):
    """Tests marked ``needs_triton`` skip where triton does not import,
    saying why."""
    if item.get_closest_marker('needs_triton'):
        from wgse_mmseg.core.wgse import triton_band_networks
        reason = triton_band_networks.unavailable()
        if reason is not None:
            pytest.skip(reason)


def pytest_addoption(parser):
    parser.addoption(
        '--gpu-targets', action='store_true',
        help='also run the tests marked gpu_targets, which compile the '
        'Triton kernels for real GPU targets (about 2 minutes of CPU); '
        '.ci/run runs them once, as their own step')


#: why a ``gpu_targets`` test is skipped without ``--gpu-targets``
_GPU_TARGETS_SKIPPED = (
    'compiles the Triton kernels for GPU targets: bash tools/run_tests.sh '
    '--gpu-targets -m gpu_targets (a step of .ci/run of its own)')


def pytest_collection_modifyitems(config, items):
    """The tests marked ``long`` first, longest first: pytest-xdist's work
    stealing takes the end of a worker's queue, so the short tests fill the
    gaps and no long test is left to run alone at the end (one started
    last kept the other worker idle 51 s). The tests marked
    ``gpu_targets`` skip unless ``--gpu-targets`` is given: what they
    check (registers, spills, instruction budgets of the compiled code)
    depends on the kernels and triton alone, not on the stack a suite runs
    on, so CI checks it once rather than in each stack's suite."""
    if not config.getoption('--gpu-targets'):
        skip = pytest.mark.skip(reason=_GPU_TARGETS_SKIPPED)
        for item in items:
            if item.get_closest_marker('gpu_targets'):
                item.add_marker(skip)

    def seconds(item):
        marker = item.get_closest_marker('long')
        return marker.args[0] if marker else 0
    items.sort(key=seconds, reverse=True)  # stable: otherwise as collected
