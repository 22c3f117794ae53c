"""mmcv.ops fallback (mmcv-lite) and weights-only loading of checkpoints."""
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

from wgse_mmseg.compat import apply_compat
from wgse_mmseg.compat.checkpoint_safety import history_buffer_statistic
from wgse_mmseg.compat.mmcv_ops_fallback import MissingCompiledOpError

HAS_COMPILED_OPS = importlib.util.find_spec('mmcv._ext') is not None
apply_compat()


@pytest.mark.skipif(HAS_COMPILED_OPS, reason='full mmcv: nothing replaced')
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
def test_compiled_only_ops_import_but_fail_clearly_on_use():
    from mmcv.ops import CrissCrossAttention, sigmoid_focal_loss
    with pytest.raises(MissingCompiledOpError, match='CrissCrossAttention'):
        CrissCrossAttention(16)
    with pytest.raises(MissingCompiledOpError, match='MMCV=full'):
        sigmoid_focal_loss(torch.zeros(1, 2), torch.zeros(1))
    from mmcv.ops.multi_scale_deform_attn import MultiScaleDeformableAttention
    with pytest.raises(MissingCompiledOpError, match='MultiScaleDeform'):
        MultiScaleDeformableAttention()


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
    processes), and no warnings from importing and building the models."""
    config = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
        os.path.abspath(__file__)))), 'configs', 'segformer_b0_wgse.py')
    env = {k: v for k, v in os.environ.items()
           if k not in ('RANK', 'WGSE_MMSEG_MMCV_NOTICE_SHOWN')}
    if rank is not None:
        env['RANK'] = rank
    proc = subprocess.run([sys.executable, '-c', QUIET_RUN, config, 'child'],
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
        'import sys, torch\n'
        'before = len(torch.serialization.get_safe_globals())\n'
        'import wgse_mmseg\n'
        'try:\n'
        '    wgse_mmseg.register_all_modules()\n'
        'except ImportError as error:\n'
        '    print(error)\n'
        'from wgse_mmseg.compat import apply_compat\n'
        'assert apply_compat() is False\n'
        'assert len(torch.serialization.get_safe_globals()) == before\n'
        'ops = sys.modules.get("mmcv.ops")\n'
        'assert not getattr(ops, "__wgse_fallback__", False)\n'
        'wgse_mmseg.core.WGSE()(torch.zeros(1, 9, 2, 2))\n',
        WGSE_MMSEG_NO_COMPAT='1')
    if not HAS_COMPILED_OPS:  # mmcv-lite
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
        'import os, sys, warnings, torch\n'
        'state = lambda: (len(torch.serialization.get_safe_globals()),\n'
        '                 "mmcv.ops" in sys.modules, len(warnings.filters),\n'
        '                 dict(os.environ))\n'
        '# what the third-party modules do on import themselves\n'
        'import cv2, mmengine.config, mmengine.runner, mmengine.logging\n'
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
    if not HAS_COMPILED_OPS:  # mmcv-lite: MMSeg needs the stand-in first
        assert 'wgse_mmseg.models imports MMSeg' in out
        assert 'wgse_mmseg.register_all_modules()' in out
        assert "imports=['wgse_mmseg.mmseg_layer']" in out
