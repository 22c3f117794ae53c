"""The compatibility layer on the installed stack: the mmcv.ops stand-in,
weights-only loading of checkpoints (mmengine's loader included), ``mmseg::``
scopes, and the check that one stack is installed."""
import ast
import importlib
import importlib.util
import io
import os
import pickle
import subprocess
import sys

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from mmengine.logging import HistoryBuffer, MessageHub

from wgse_mmseg.compat import (apply_compat,
                               guard_mmengine_checkpoint_loader,
                               map_scopes_to_installed_distributions)
from wgse_mmseg.compat.checkpoint_safety import (history_buffer_statistic,
                                                 weights_only_load)
from wgse_mmseg.compat.mmcv_ops_fallback import (PURE_PYTHON_OPS,
                                                 MissingCompiledOpError,
                                                 _ops_imports, stand_in_names)

HAS_COMPILED_OPS = importlib.util.find_spec('mmcv._ext') is not None
#: an MMSeg that cannot import without mmcv.ops, and no compiled ops
NEEDS_STAND_IN = not HAS_COMPILED_OPS and bool(stand_in_names())
apply_compat()


@pytest.mark.skipif(not NEEDS_STAND_IN or 'point_sample' not in
                    stand_in_names(),
                    reason='full mmcv, or an MMSeg that needs no stand-in')
def test_fallback_supplies_mmcv_point_sample_and_mmseg_imports():
    import mmcv.ops
    import mmseg.models  # noqa: F401  imports mmcv.ops at module level
    assert mmcv.ops.__wgse_fallback__
    features = torch.arange(2 * 3 * 4 * 5, dtype=torch.float32).reshape(
        2, 3, 4, 5)
    points = torch.rand(2, 7, 2)
    got = mmcv.ops.point_sample(features, points, align_corners=False)
    # point_sample maps [0, 1] points onto grid_sample's [-1, 1]
    want = F.grid_sample(features, (2 * points - 1).unsqueeze(2),
                         align_corners=False).squeeze(3)
    torch.testing.assert_close(got, want)


@pytest.mark.skipif(HAS_COMPILED_OPS, reason='full mmcv: nothing replaced')
def test_the_stand_in_holds_only_the_names_mmseg_imports():
    """Where a stand-in is installed, it answers exactly the names MMSeg
    imports (compiled-only ones raise when used); any other name is absent,
    as under mmcv-lite, so other libraries' probes see no op."""
    needed = stand_in_names()
    if not needed:  # an MMSeg that guards its mmcv.ops imports: no stand-in
        with pytest.raises(ImportError):
            import mmcv.ops  # noqa: F401
        return
    import mmcv.ops  # noqa: F811  (the branch above returned)
    assert mmcv.ops.__wgse_fallback__
    public = {name for name in vars(mmcv.ops) if not name.startswith('_')}
    assert public == needed
    for name in needed - set(PURE_PYTHON_OPS):
        with pytest.raises(MissingCompiledOpError, match=name):
            getattr(mmcv.ops, name)()
    with pytest.raises(MissingCompiledOpError, match='MMCV=full'):
        getattr(mmcv.ops, sorted(needed - set(PURE_PYTHON_OPS))[0])()
    for name in ('TotallyMadeUpOpName', 'nms', 'RoIAlign', 'SyncBatchNorm',
                 'bilinear_grid_sample', '__wrapped__'):
        assert not hasattr(mmcv.ops, name)
        with pytest.raises(ImportError):
            exec(f'from mmcv.ops import {name}', {})
    for module in ('mmcv.ops.nms', 'mmcv.ops.multi_scale_deform_attn'):
        with pytest.raises(ImportError):
            importlib.import_module(module)


def test_mmseg_imports_with_what_the_stand_in_holds():
    """The packages of the installed MMSeg that hold its mmcv.ops imports
    (decode heads, losses, the optimiser constructor, utils) import."""
    for name in ('mmseg.models', 'mmseg.engine', 'mmseg.utils', 'mmseg.apis'):
        importlib.import_module(name)


MODULE_SOURCE = """
from mmcv.ops import top_level
if flag:
    from mmcv.ops import in_if, other
try:
    from mmcv.ops import only_module_not_found, twice
except ModuleNotFoundError:
    pass
try:
    from mmcv.ops import guarded, twice
except (OSError, ImportError):
    pass
try:
    from mmcv.ops import guarded_by_exception
except Exception:
    pass
try:
    import x
except ImportError:
    from mmcv.ops import in_handler
try:
    from mmcv.ops import not_caught
except KeyError:
    pass
def f():
    from mmcv.ops import in_function
class C:
    from mmcv.ops import in_class
from mmcv.ops.nms import by_path
"""


def test_the_names_mmseg_needs_are_read_off_its_source():
    """Each import run at a module's import, with its weakest guard;
    imports in functions and classes (run later) are left out."""
    assert _ops_imports(ast.parse(MODULE_SOURCE)) == {
        'top_level': 'unguarded', 'in_if': 'unguarded', 'other': 'unguarded',
        'only_module_not_found': 'ModuleNotFoundError',
        'twice': 'ModuleNotFoundError', 'guarded': 'ImportError',
        'guarded_by_exception': 'ImportError', 'in_handler': 'unguarded',
        'not_caught': 'unguarded'}


QUIET_RUN = (
    'import subprocess, sys\n'
    'import wgse_mmseg\n'
    'wgse_mmseg.register_all_modules()\n'
    'from mmseg.registry import MODELS\n'
    'from wgse_mmseg.utils.config import load_config\n'
    'MODELS.build(load_config(sys.argv[1]).model)\n'
    'if len(sys.argv) > 2:  # a process started from this one\n'
    '    subprocess.run([sys.executable, "-c", "import wgse_mmseg; '
    'wgse_mmseg.register_all_modules()"], check=True)\n')


@pytest.mark.parametrize('rank', [None, '1'])
def test_a_run_is_quiet(rank):
    """One line about mmcv-lite per run (none in other ranks or child
    processes), and no warnings from importing and building the models.
    The run without RANK starts a child process; rank 1's children inherit
    its RANK, which its own silence already checks."""
    config = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
        os.path.abspath(__file__)))), 'configs', 'segformer_b0_wgse.py')
    env = {k: v for k, v in os.environ.items()
           if k not in ('RANK', 'WGSE_MMSEG_MMCV_NOTICE_SHOWN')}
    if rank is not None:
        env['RANK'] = rank
    child = ['child'] if rank is None else []
    proc = subprocess.run([sys.executable, '-c', QUIET_RUN, config, *child],
                          capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    notices = [line for line in lines if line.startswith('wgse_mmseg:')]
    assert len(notices) == (0 if HAS_COMPILED_OPS or rank else 1), lines
    others = [line for line in lines if line not in notices]
    assert not [line for line in others
                if 'Warning' in line and 'avg_non_ignore' not in line], others


@pytest.mark.skipif(not HAS_COMPILED_OPS, reason='needs full mmcv')
def test_full_mmcv_is_left_alone():
    import mmcv.ops
    assert not getattr(mmcv.ops, '__wgse_fallback__', False)


def test_mmengine_checkpoint_contents_load_weights_only():
    hub = MessageHub.get_instance('wgse_checkpoint_test')
    for value in (1.0, 2.5, np.float64(3.0)):
        hub.update_scalar('train/loss', value)
    checkpoint = dict(
        state_dict={'w': torch.ones(2)},
        message_hub=hub.state_dict(),
        meta=dict(epoch=np.int64(3), array=np.arange(3.0)))
    buffer = io.BytesIO()
    torch.save(checkpoint, buffer)
    buffer.seek(0)
    loaded = torch.load(buffer, weights_only=True)
    logs = loaded['message_hub']['log_scalars']['train/loss']
    assert isinstance(logs, HistoryBuffer)
    assert logs.mean() == pytest.approx(6.5 / 3)


class _Payload:
    """Pickles as ``getattr(HistoryBuffer, '__init__')``: not a statistic."""

    def __reduce__(self):
        return getattr, (HistoryBuffer, '__init__')


def test_getattr_stays_restricted_to_history_buffer_statistics():
    assert history_buffer_statistic(HistoryBuffer, 'min') is HistoryBuffer.min
    with pytest.raises(pickle.UnpicklingError):
        history_buffer_statistic(HistoryBuffer, '__init__')
    buffer = io.BytesIO()
    torch.save({'x': _Payload()}, buffer)
    buffer.seek(0)
    with pytest.raises(pickle.UnpicklingError, match='getattr'):
        torch.load(buffer, weights_only=True)


#: Python counting the entries of torch's allowlist this package adds (not
#: those torch adds itself when MMSeg imports torch.distributed.tensor)
OURS = ('ours = lambda: len([g for g in torch.serialization.get_safe_globals()'
        ' if "HistoryBuffer" in repr(g) or "wgse_mmseg" in repr(g)])\n')


def _run(code, **env):
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True,
                          text=True, env=dict(os.environ, **env))
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout


def test_importing_the_package_and_core_changes_nothing():
    """``import wgse_mmseg`` and core patch nothing and import nothing of
    OpenMMLab; registering the MMSeg layer applies the patches."""
    _run('import sys, torch\n'
         'before = len(torch.serialization.get_safe_globals())\n'
         'import wgse_mmseg, wgse_mmseg.core\n'
         'wgse_mmseg.core.WGSE()(torch.zeros(1, 9, 2, 2))\n'
         'assert len(torch.serialization.get_safe_globals()) == before\n'
         'assert not [m for m in sys.modules if m.split(".")[0] in '
         '("mmcv", "mmseg", "mmengine")], "OpenMMLab imported"\n'
         'wgse_mmseg.register_all_modules()\n'
         'from mmseg.registry import MODELS\n'
         'assert MODELS.get("WGSE") is wgse_mmseg.core.WGSE\n'
         'assert len(torch.serialization.get_safe_globals()) > before\n')


def test_patches_are_applied_once_and_can_be_turned_off():
    """``WGSE_MMSEG_NO_COMPAT=1``: torch's allowlist is left alone and no
    ``mmcv.ops`` stand-in is installed; core still works, and under
    mmcv-lite the MMSeg layer says why it cannot import."""
    out = _run(
        'import sys, torch\n' + OURS +
        'import wgse_mmseg\n'
        'try:\n'
        '    wgse_mmseg.register_all_modules()\n'
        'except ImportError as error:\n'
        '    print(error)\n'
        'from wgse_mmseg.compat import apply_compat\n'
        'assert apply_compat() is False\n'
        'assert ours() == 0\n'
        'ops = sys.modules.get("mmcv.ops")\n'
        'assert not getattr(ops, "__wgse_fallback__", False)\n'
        'import wgse_mmseg.core\n'
        'wgse_mmseg.core.WGSE()(torch.zeros(1, 9, 2, 2))\n',
        WGSE_MMSEG_NO_COMPAT='1')
    if NEEDS_STAND_IN:  # mmcv-lite under MMSeg 1.2.2
        assert 'WGSE_MMSEG_NO_COMPAT is set' in out
        assert 'wgse_mmseg.datasets needs mmcv.ops' in out
    # and by default, applying again changes nothing
    count = len(torch.serialization.get_safe_globals())
    assert apply_compat() is True
    assert len(torch.serialization.get_safe_globals()) == count


def test_importing_a_layer_module_patches_nothing():
    """The patches come from an explicit call only: importing the layer's
    packages leaves torch's allowlist, ``sys.modules``, the warning filters
    and the environment as they were; under mmcv-lite a package that imports
    MMSeg names the call instead. ``wgse_mmseg.mmseg_layer``, what a config
    imports, is that call."""
    out = _run(
        'import os, sys, warnings, torch\n' + OURS +
        'state = lambda: (ours(),\n'
        '                 "mmcv.ops" in sys.modules, len(warnings.filters),\n'
        '                 dict(os.environ))\n'
        '# what the third-party modules do on import themselves (MMSeg\'s\n'
        '# own, where it imports without the set-up)\n'
        'import cv2, mmengine.config, mmengine.runner, mmengine.logging\n'
        f'if not {NEEDS_STAND_IN}:\n'
        '    import mmseg.apis, mmseg.models, mmseg.datasets, mmseg.engine\n'
        '    import mmseg.evaluation, mmseg.visualization\n'
        'before = state()\n'
        'import wgse_mmseg.utils.config, wgse_mmseg.utils.spike_settings\n'
        'try:\n'
        '    import wgse_mmseg.models\n'
        'except ImportError as error:\n'
        '    print(error)\n'
        'assert state() == before, "an import patched the process"\n'
        'import wgse_mmseg.mmseg_layer\n'
        'assert state()[0] > before[0]\n'
        'from mmseg.registry import MODELS\n'
        'assert MODELS.get("WGSE") is wgse_mmseg.core.WGSE\n'
        'print("registered")\n')
    assert 'registered' in out
    if NEEDS_STAND_IN:  # mmcv-lite: MMSeg 1.2.2 needs the stand-in first
        assert 'wgse_mmseg.models imports MMSeg' in out
        assert 'wgse_mmseg.register_all_modules()' in out
        assert "imports=['wgse_mmseg.mmseg_layer']" in out


class _OpensAFile:
    """Pickles as ``open(path, 'w')``: code run by a full unpickling."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return open, (self.path, 'w')


def _code_checkpoint(tmp_path):
    marker = tmp_path / 'ran'
    path = str(tmp_path / 'downloaded.pth')
    torch.save({'state_dict': {}, 'meta': {'x': _OpensAFile(marker)}}, path)
    return path, marker


def test_mmengines_loader_never_unpickles_a_checkpoint_in_full(tmp_path):
    """The installed mmengine's loader, as the runner calls it, refuses a
    checkpoint that pickles code and runs none of it (onedl-mmengine's
    retry with ``weights_only=False`` is never reached)."""
    from mmengine.runner.checkpoint import _load_checkpoint
    path, marker = _code_checkpoint(tmp_path)
    with pytest.raises(pickle.UnpicklingError):
        _load_checkpoint(path, map_location='cpu')
    assert not marker.exists()


def test_a_loader_that_retries_in_full_is_replaced(tmp_path, monkeypatch):
    """The guard finds a loader that falls back to full unpickling by what
    it does, replaces it, and leaves a weights-only loader alone."""
    from mmengine.runner import checkpoint

    def retrying(file, map_location=None, weights_only=None):
        try:
            return torch.load(file, map_location=map_location,
                              weights_only=True)
        except pickle.UnpicklingError:
            return torch.load(file, map_location=map_location,
                              weights_only=False)

    monkeypatch.setattr(checkpoint, '_safe_torch_load', retrying,
                        raising=False)
    monkeypatch.setattr(checkpoint, 'load_from_local',
                        lambda path, map_location: checkpoint._safe_torch_load(
                            path, map_location=map_location))
    path, marker = _code_checkpoint(tmp_path)
    assert guard_mmengine_checkpoint_loader() is True
    assert checkpoint._safe_torch_load is weights_only_load
    with pytest.raises(pickle.UnpicklingError):
        checkpoint.load_from_local(path, map_location='cpu')
    with pytest.raises(pickle.UnpicklingError, match='weights_only=False'):
        weights_only_load(path, weights_only=False)
    assert not marker.exists()
    assert guard_mmengine_checkpoint_loader() is False  # now weights-only


def test_mmseg_bases_resolve_through_the_installed_distribution(
        tmp_path, monkeypatch):
    """``mmseg::`` reaches the distribution that holds ``mmseg`` (whatever
    its name), also where mmengine names another."""
    from importlib import metadata

    from mmengine.config import Config
    from mmengine.config.utils import MODULE2PACKAGE
    holders = {dist.metadata['Name'] for dist in metadata.distributions()
               if any(str(f) == 'mmseg/__init__.py' for f in dist.files or ())}
    assert len(holders) == 1
    config = tmp_path / 'child.py'
    config.write_text("_base_ = ['mmseg::_base_/models/pspnet_r50-d8.py']\n")
    assert Config.fromfile(str(config)).model.decode_head.type == 'PSPHead'
    monkeypatch.setitem(MODULE2PACKAGE, 'mmseg', 'no-such-distribution')
    assert map_scopes_to_installed_distributions() == {'mmseg': holders.pop()}
    assert Config.fromfile(str(config)).model.decode_head.type == 'PSPHead'
    assert map_scopes_to_installed_distributions() == {}


def test_distributions_of_both_stacks_are_refused(monkeypatch):
    """mmsegmentation installed over onedl-mmsegmentation (what an
    install_requires naming it did): a clear ImportError naming both."""
    from wgse_mmseg import openmmlab_stack
    versions = {'mmsegmentation': '1.2.2', 'mmengine': '0.10.7',
                'onedl-mmsegmentation': '1.4.2', 'onedl-mmcv': '2.3.6'}

    def version(name):
        if name not in versions:
            raise openmmlab_stack.metadata.PackageNotFoundError(name)
        return versions[name]

    monkeypatch.setattr(openmmlab_stack.metadata, 'version', version)
    openmmlab_stack.installed_stacks.cache_clear()
    try:
        with pytest.raises(ImportError, match='both OpenMMLab stacks') as err:
            openmmlab_stack.require_openmmlab('wgse_mmseg.models')
        assert 'onedl-mmsegmentation 1.4.2' in str(err.value)
        assert 'openmmlab: mmengine 0.10.7, mmsegmentation 1.2.2' in str(
            err.value)
    finally:
        openmmlab_stack.installed_stacks.cache_clear()
