"""tools/analysis_tools/benchmark_wgse.py: the side-by-side table and the
agreement check (tiny shapes; the issue's shapes are for the published run)."""
import json
import os.path as osp
import subprocess
import sys

import pytest
import torch

from wgse_mmseg.core.wgse import compiled_band_networks

pytest.importorskip('pytorch_wavelets')
ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
#: a plain environment: no TRITON_INTERPRET, so no Triton row on the CPU;
#: the checkout's packages (the library and the measurement wing)
ENV = {'OMP_NUM_THREADS': '1', 'PATH': '/usr/bin:/bin', 'PYTHONPATH': ROOT}
CPU_BACKENDS = {'torch'} | (
    {'compiled'} if compiled_band_networks.unavailable() is None else set())


def _benchmark(*args):
    return subprocess.run(
        [sys.executable,
         osp.join(ROOT, 'tools', 'analysis_tools', 'benchmark_wgse.py')] +
        list(args), capture_output=True, text=True, cwd=ROOT, env=ENV)


@pytest.mark.long(30)
def test_table_and_json_report_ratios_and_agreement(tmp_path):
    out = tmp_path / 'wgse.json'
    proc = _benchmark('--shapes', '1x41x4x6', '1x12x3x3', '--repeat', '1',
                      '--out', str(out))
    assert proc.returncode == 0, proc.stderr
    assert 'pytorch_wavelets + per-pixel nn.Conv1d' in proc.stdout
    assert 'output agreement' in proc.stdout
    report = json.loads(out.read_text())
    assert report['machine']['torch'] and report['machine']['device'] == 'cpu'
    assert {r['impl'] for r in report['results']} == {'reference'} | \
        CPU_BACKENDS
    for row in report['results']:
        assert row['device'] == 'cpu'
        assert row['median_s'] > 0 and row['peak_mib'] >= 0
        if row['impl'] != 'reference':
            # the backend column says what ran
            assert row['backend'] == row['impl']
            assert row['speedup'] > 0 and 'memory_ratio' in row
    # Same weights, same input: the reference design's output (its extra
    # sample for odd T dropped) equals WGSE's, and so do the gradients.
    assert len(report['agreement']) == 2
    for check in report['agreement']:
        assert check['max_abs_output_diff'] < 1e-4
        assert check['max_rel_grad_diff'] < 1e-3


def test_torch_backend_memory_per_pixel_on_cpu(tmp_path):
    """The 'torch' backend's forward+backward at 1x129x128x128 grows the
    peak RSS by at most 8 KiB per pixel (the per-pixel module path: 84):
    activations are recomputed chunk by chunk, never kept for all pixels."""
    out = tmp_path / 'memory.json'
    proc = _benchmark('--impls', 'torch', '--shapes', '1x129x128x128',
                      '--repeat', '1', '--out', str(out))
    assert proc.returncode == 0, proc.stderr
    row, = json.loads(out.read_text())['results']
    assert row['backend'] == 'torch'
    assert 0 < row['kib_per_pixel'] <= 8, row


@pytest.mark.parametrize('args, message', [
    (['--shapes', '4x41x128'], 'argument --shapes: must be (B, T, H, W)'),
    (['--impls', 'triton'], 'cannot run on cpu'),
    pytest.param(['--device', 'cuda'], 'no CUDA device',
                 marks=pytest.mark.skipif(torch.cuda.is_available(),
                                          reason='a GPU is present')),
])
def test_usage_errors(args, message, monkeypatch, capsys, load_tool):
    """The tool's own checks, in this process (the plain environment's: no
    Triton on the CPU without TRITON_INTERPRET, read when asked)."""
    monkeypatch.delenv('TRITON_INTERPRET', raising=False)
    tool = load_tool('tools/analysis_tools/benchmark_wgse.py')
    with pytest.raises(SystemExit) as exit_info:
        tool.main(args)
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err
