"""wgse_mmseg.core imports and runs where mmengine, mmsegmentation and mmcv
cannot be imported (a GPU machine with torch alone), and the MMSeg layer
then says what to install. The stack is hidden from a fresh interpreter by
a ``sitecustomize`` that refuses to import it, so every process of a tool
(the WGSE benchmark spawns workers) sees the same."""
import json
import os.path as osp
import subprocess
import sys

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SCRIPT = '''
import json, sys
import numpy as np, torch
import wgse_mmseg
from wgse_mmseg.core import TFI, TFP, WGSE, simulate_spikes, wavedec
from wgse_mmseg.fileio import load_spikes, save_spikes
spikes, _ = simulate_spikes(np.full((2, 6, 8), 0.5), 41, seed=0)
save_spikes(sys.argv[1], spikes)
stream = torch.from_numpy(load_spikes(sys.argv[1]))[None].float()
model = WGSE(backend='torch')
out = model(stream)
out.square().mean().backward()
try:
    import wgse_mmseg.models  # noqa: F401
    error = None
except ImportError as exc:
    error = str(exc)
print(json.dumps(dict(
    shape=list(out.shape), finite=bool(torch.isfinite(out).all()),
    grads=all(p.grad is not None for p in model.parameters()),
    tfp=list(TFP(window=5)(stream).shape), tfi=list(TFI()(stream).shape),
    bands=len(wavedec(torch.zeros(41), 'db8', level=5, mode='zero')),
    error=error, loaded=sorted({m.split('.')[0] for m in sys.modules
                                if m.split('.')[0] in ('mmengine', 'mmseg',
                                                       'mmcv')}))))
'''


def test_core_runs_and_the_mmseg_layer_says_what_to_install(without_openmmlab,
                                                            tmp_path):
    proc = subprocess.run(
        [sys.executable, '-c', SCRIPT, str(tmp_path / 'clip.spk')],
        capture_output=True, text=True, env=without_openmmlab, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report['shape'] == [1, 41, 6, 8] and report['finite']
    assert report['grads']
    assert report['tfp'] == report['tfi'] == [1, 41, 6, 8]
    assert report['bands'] == 6
    assert report['loaded'] == []  # nothing of the stack was imported
    for name in ('wgse_mmseg.models', 'mmengine', 'mmsegmentation',
                 'wgse_mmseg.core', 'tools/setup_env.sh'):
        assert name in report['error']


def test_importing_a_layer_module_directly_names_what_is_missing(
        without_openmmlab, tmp_path):
    proc = subprocess.run(
        [sys.executable, '-c', 'import wgse_mmseg.datasets'],
        capture_output=True, text=True, env=without_openmmlab, cwd=tmp_path)
    assert proc.returncode != 0
    assert 'ImportError: wgse_mmseg.datasets needs' in proc.stderr


def test_the_wgse_benchmark_runs_without_the_stack(without_openmmlab,
                                                   tmp_path):
    proc = subprocess.run(
        [sys.executable,
         osp.join(ROOT, 'tools', 'analysis_tools', 'benchmark_wgse.py'),
         '--impls', 'torch', '--shapes', '1x12x3x4', '--repeat', '1'],
        capture_output=True, text=True, env=without_openmmlab, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "WGSE, backend='torch'" in proc.stdout


BENCHMARKS = '''
import json, sys
from types import SimpleNamespace
import numpy as np
from wgse_bench import gpu_report, machine, simulator, timing, wgse
args = SimpleNamespace(height=6, width=8, steps=12, repeat=1, device='cpu',
                       load_shape=(12, 6, 8))
frames = np.random.default_rng(0).random((3, 6, 8))
lines = (simulator.header(args) + simulator.simulator_rows(args, frames[1:2],
                                                           frames)
         + simulator.load_rows(args, frames[1:2]))
record = machine.machine_record('cpu')
correctness = gpu_report.check_correctness((1, 12, 3, 5), 'cpu')
print(json.dumps(dict(
    lines=lines, record=record, rows=correctness['rows'],
    backends=wgse.available_backends('cpu'),
    loaded=sorted({m.split('.')[0] for m in sys.modules
                   if m.split('.')[0] in ('mmengine', 'mmseg', 'mmcv')}))))
'''


def test_the_benchmarks_run_without_the_stack(without_openmmlab, tmp_path):
    """The benchmark package's core parts (the simulator's tables, the
    machine record, the GPU report's correctness section) import and run
    where OpenMMLab cannot be imported."""
    proc = subprocess.run([sys.executable, '-c', BENCHMARKS],
                          capture_output=True, text=True,
                          env=without_openmmlab, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report['loaded'] == []
    text = '\n'.join(report['lines'])
    for expected in ('NumPy step loop', '+ jitter', 'load .npz',
                     'integrate-and-fire:'):
        assert expected in text
    record = report['record']
    assert record['device'] == 'cpu' and record['torch']
    assert record['cpu_count'] >= 1 and record['torch_threads'] >= 1
    assert 'torch' in report['backends']
    assert 'reference' not in report['backends']
    assert {r['backend'] for r in report['rows']} >= {'torch'}
    # full float32 judged, TF32, bf16 and fp16 measured (gpu_report's note)
    torch_rows = {r['precision']: r for r in report['rows']
                  if r['backend'] == 'torch'}
    assert torch_rows.pop('ieee')['ok'] is True
    assert set(torch_rows) == {'tf32', 'bf16', 'fp16'}
    assert all(r['ok'] is None and r['max_rel_error'] < 1e-2
               for r in torch_rows.values())
