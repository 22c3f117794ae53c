"""Let torch's weights-only loader open mmengine checkpoints, and no more.

Since torch 2.6, ``torch.load`` defaults to ``weights_only=True``, which
refuses any Python object outside an allowlist. mmengine 0.10.7 checkpoints
hold, besides tensors, the message hub's ``HistoryBuffer`` logs and the NumPy
arrays and scalars inside them, so ``resume=True`` and ``load_from`` fail.
This module adds exactly those classes to torch's allowlist
(``torch.serialization.add_safe_globals``); weights-only loading stays on, and
any other object in a checkpoint is still refused.

``HistoryBuffer`` also pickles its statistics methods as
``getattr(HistoryBuffer, 'min')``. Allowing the builtin ``getattr`` would let
a checkpoint fetch any attribute of any allowed object, so the name
``builtins.getattr`` is bound to :func:`history_buffer_statistic` instead,
which returns only those methods and refuses everything else.

The list was read off real checkpoints with
``torch.serialization.get_unsafe_globals_in_checkpoint``;
``tests/compat/test_compat.py`` loads such contents weights-only, and
``tests/tools/test_mim_end_to_end.py`` resumes a real run from its checkpoint.

mmengine's own checkpoint loader must not undo this: onedl-mmengine 0.10.12's
``_safe_torch_load`` retries a load that the weights-only unpickler refused
with ``weights_only=False``, which runs whatever the file pickles.
:func:`guard_mmengine_checkpoint_loader` finds out whether the installed
mmengine does that by loading a probe checkpoint whose pickle calls a
harmless function of this module (:func:`_full_unpickling_reached`) and
seeing whether it ran; only then it replaces the loader with
:func:`weights_only_load`, and checks with the probe again.
"""
import contextlib
import importlib
import io
import os
import pickle
import tempfile
import warnings
from typing import List

import torch

__all__ = []

#: ``module:qualname`` of every non-tensor class an mmengine 0.10.7
#: checkpoint pickles (NumPy spells its core ``numpy.core`` or
#: ``numpy._core`` depending on the version that wrote the file).
MMENGINE_CHECKPOINT_GLOBALS = (
    'mmengine.logging.history_buffer:HistoryBuffer',
    'numpy:ndarray',
    'numpy:dtype',
    'numpy.core.multiarray:_reconstruct',
    'numpy.core.multiarray:scalar',
    'numpy._core.multiarray:_reconstruct',
    'numpy._core.multiarray:scalar',
) + tuple(  # NumPy 2 builds dtype objects of these classes (not GLOBALs, so
    # get_unsafe_globals_in_checkpoint does not list them)
    f'numpy.dtypes:{kind}DType'
    for kind in ('Float64', 'Float32', 'Float16', 'Int64', 'Int32', 'Int16',
                 'Int8', 'UInt64', 'UInt32', 'UInt16', 'UInt8', 'Bool'))


def history_buffer_statistic(owner, name: str):
    """``getattr`` restricted to ``HistoryBuffer``'s statistics methods."""
    from mmengine.logging import HistoryBuffer
    # The built-in statistics are only entered into _statistics_methods when
    # a first buffer is made, which may not have happened before loading.
    statistics = {'min', 'max', 'mean', 'current'}
    statistics.update(HistoryBuffer._statistics_methods)
    if (owner is HistoryBuffer or isinstance(owner, HistoryBuffer)) and \
            name in statistics:
        return getattr(owner, name)
    raise pickle.UnpicklingError(
        f'checkpoint asks for getattr({owner!r}, {name!r}); only '
        f'HistoryBuffer statistics methods are allowed')


def _resolve(spec: str):
    module_name, _, qualname = spec.partition(':')
    try:
        obj = importlib.import_module(module_name)
    except ImportError:
        return None
    for part in qualname.split('.'):
        obj = getattr(obj, part, None)
        if obj is None:
            return None
    return obj


def allow_mmengine_checkpoints() -> List[str]:
    """Allowlist the classes of :data:`MMENGINE_CHECKPOINT_GLOBALS`.

    Returns the specs that exist in this environment (NumPy 1 and 2 name
    some differently). Idempotent.
    """
    add_safe_globals = getattr(torch.serialization, 'add_safe_globals', None)
    if add_safe_globals is None:  # torch < 2.4 has no weights-only default
        return []
    allowed, found = [], []
    for spec in MMENGINE_CHECKPOINT_GLOBALS:
        obj = _resolve(spec)
        if obj is None:
            continue
        module_name, _, qualname = spec.partition(':')
        # Register under the name the pickle uses, which may differ from
        # where the object now lives (numpy.core -> numpy._core).
        allowed.append((obj, f'{module_name}.{qualname}'))
        found.append(spec)
    allowed.append((history_buffer_statistic, 'builtins.getattr'))
    add_safe_globals(allowed)
    return found


def weights_only_load(file, map_location=None, weights_only=None):
    """mmengine's ``_safe_torch_load(file, map_location, weights_only)``
    without a way to full unpickling: ``torch.load(weights_only=True)`` with
    the allowlist above, as mmengine 0.10.7 loads under torch >= 2.6. What
    it refuses raises torch's ``pickle.UnpicklingError``, as there (the
    configs' runner names the file: :class:`wgse_mmseg.engine.SpikeRunner`);
    so does a caller asking for ``weights_only=False``."""
    if weights_only is False:
        raise pickle.UnpicklingError(
            'refused to load a checkpoint with weights_only=False (it would '
            'run code from the file); wgse_mmseg loads checkpoints '
            'weights-only')
    return torch.load(file, map_location=map_location, weights_only=True)


_probe_runs = []


def _full_unpickling_reached():
    """What the probe checkpoint calls when it is unpickled in full."""
    _probe_runs.append(True)
    return 'unpickled in full'


class _FullUnpicklingProbe:
    def __reduce__(self):
        return _full_unpickling_reached, ()


def _loader_unpickles_in_full(loader) -> bool:
    """Whether ``loader(path, map_location)`` runs code from a checkpoint."""
    buffer = io.BytesIO()
    torch.save({'probe': _FullUnpicklingProbe()}, buffer)
    del _probe_runs[:]
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, 'probe.pth')
        with open(path, 'wb') as f:
            f.write(buffer.getvalue())
        try:  # quietly: onedl-mmengine print()s its fallback
            with warnings.catch_warnings(), \
                    contextlib.redirect_stdout(io.StringIO()):
                warnings.simplefilter('ignore')
                loader(path, map_location='cpu')
        except Exception:  # refused: what a safe loader does
            pass
    return bool(_probe_runs)


def guard_mmengine_checkpoint_loader() -> bool:
    """Replace mmengine's checkpoint loader by :func:`weights_only_load`
    where it unpickles a refused checkpoint in full; True if it did.

    Raises:
        RuntimeError: the loader unpickles in full and cannot be replaced
            (an mmengine without ``_safe_torch_load``).
    """
    from mmengine.runner import checkpoint
    if not _loader_unpickles_in_full(checkpoint.load_from_local):
        return False
    if hasattr(checkpoint, '_safe_torch_load'):
        checkpoint._safe_torch_load = weights_only_load
    if _loader_unpickles_in_full(checkpoint.load_from_local):
        raise RuntimeError(
            "mmengine's checkpoint loader (mmengine.runner.checkpoint."
            "load_from_local) unpickles checkpoints in full, which would run "
            "code from any checkpoint, and wgse_mmseg cannot replace it in "
            "this mmengine; use the pinned stacks (docs/install.md)")
    return True
