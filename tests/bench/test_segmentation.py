"""tools/analysis_tools/benchmark.py and the measurements of
wgse_bench.segmentation, with the benchmarks' one timer and
Markdown tables."""
import json
import os.path as osp
import subprocess
import sys

import pytest
import torch
import torch.nn as nn

from mmseg.registry import MODELS
from wgse_bench.markdown import markdown_table
from wgse_bench.segmentation import (build_model, count_flops,
                                     inference_parameters,
                                     measure_enhancer_step,
                                     measure_train_step)
from wgse_bench.timing import summarize, time_calls

pytestmark = pytest.mark.usefixtures('single_thread')

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
PSPNET_WGSE = 'pspnet_wgse'
SEGFORMER_WGSE = 'segformer_b0_wgse'
SEGFORMER_RAW = 'segformer_b0_raw'
TINY = dict(num_steps=9, crop_size='32,64')


def config_path(name):
    return osp.join(ROOT, 'configs', f'{name}.py')


def count(module):
    return sum(p.numel() for p in module.parameters())


@pytest.mark.long(28)
def test_cli_prints_the_table_and_writes_json(tmp_path):
    out = tmp_path / 'bench.json'
    proc = subprocess.run(
        [sys.executable,
         osp.join(ROOT, 'tools', 'analysis_tools', 'benchmark.py'),
         config_path(SEGFORMER_WGSE), '--crop', '32', '64', '--repeat',
         '1', '--warmup', '0', '--threads', '1', '--cfg-options',
         'num_steps=9', 'model.data_preprocessor.enhancer.dim=2', '--out',
         str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    table = proc.stdout
    for header in ('params (M)', 'enh. backend', 'GFLOPs', 'enh. GFLOPs',
                   'latency ms (b1)',
                   'throughput img/s', 'train step ms', 'enh. share',
                   'peak mem MB'):
        assert header in table
    assert f'| {SEGFORMER_WGSE} | 9 | 32x64 |' in table
    assert 'torch 2.' in table and 'mmsegmentation' in table
    assert 'CPU:' in table and '1 torch threads' in table

    report = json.loads(out.read_text())
    assert report['settings']['repeat'] == 1
    assert report['environment']['torch'] == torch.__version__
    result, = report['results']
    wgse = MODELS.build(dict(type='WGSE', dim=2, wavelet='db8', level=5,
                             mode='zero', kernel_size=3, hidden_channels=32))
    assert result['enhancer'] == 'WGSE'
    assert result['enhancer_backend'] == 'torch'  # dim=2: nn.Conv3d
    row, = [line for line in table.splitlines()
            if line.startswith(f'| {SEGFORMER_WGSE}')]
    assert row.split('|')[6].strip() == 'torch'  # the 'enh. backend' cell
    assert result['enhancer_params'] == count(wgse)
    assert result['num_steps'] == 9 and result['crop'] == [32, 64]
    assert result['batch_size'] == 4
    assert result['flops'] > result['enhancer_flops'] > 0
    for key in ('latency_ms', 'throughput_img_s', 'train_step_ms',
                'enhancer_step_ms'):
        assert len(result[key]['samples']) == 1 and result[key]['median'] > 0
    # Two separately timed medians: their ratio is not bounded by 1 when the
    # enhancer dominates a tiny step, so check how it is derived, not a range.
    assert result['enhancer_share'] == pytest.approx(
        result['enhancer_step_ms']['median']
        / result['train_step_ms']['median'])
    assert result['memory']['kind'].startswith('cpu_peak_rss')
    assert result['memory']['peak_mb'] > 0


def test_summarize_is_median_and_median_absolute_deviation():
    summary = summarize([1.0, 2.0, 3.0, 10.0])
    assert summary['median'] == 2.5 and summary['mad'] == 1.0
    assert summary['samples'] == [1.0, 2.0, 3.0, 10.0]
    with pytest.raises(ValueError, match='repeat'):
        summarize([])


def test_time_calls_warms_up_then_times_each_repeat():
    calls = []
    timings = time_calls(lambda: calls.append(1) or len(calls),
                         torch.device('cpu'), repeat=3, warmup=2)
    assert len(calls) == 5
    assert len(timings.wall) == len(timings.cpu) == 3
    assert all(s >= 0 for s in timings.wall + timings.cpu)
    assert timings.result == 5  # the last call's
    with pytest.raises(ValueError, match='repeat must be an integer >= 1'):
        time_calls(lambda: None, torch.device('cpu'), repeat=0, warmup=0)


def test_flops_split_between_enhancer_and_segmentor():
    _, raw = build_model(config_path(SEGFORMER_RAW), TINY)
    base = count_flops(raw, 9, (32, 64))
    assert base['enhancer'] == 0 and base['total'] > 0

    raw.data_preprocessor.enhancer = MODELS.build(dict(type='TFP'))
    tfp = count_flops(raw, 9, (32, 64))
    assert tfp['total'] == base['total'] and tfp['enhancer'] == 0
    assert 'aten::cumsum' in tfp['uncounted_ops']  # listed, not hidden

    raw.data_preprocessor.enhancer = MODELS.build(dict(type='WGSE', dim=2))
    with_wgse = count_flops(raw, 9, (32, 64))
    assert with_wgse['enhancer'] > 0
    assert with_wgse['total'] == base['total'] + with_wgse['enhancer']

    # dim=1 with backend='auto': the compiled kernel is opaque to tracing,
    # so while tracing 'auto' runs the nn.Conv1d modules, which are counted
    raw.data_preprocessor.enhancer = MODELS.build(dict(type='WGSE'))
    wgse_1d = count_flops(raw, 9, (32, 64))
    assert wgse_1d['enhancer'] > 0 and wgse_1d['note'] is None


class Untraceable(nn.Module):

    def forward(self, spikes):
        if torch.jit.is_tracing():
            raise RuntimeError('a custom kernel')
        return spikes


def test_flops_of_an_untraceable_enhancer_are_unknown_not_wrong():
    _, model = build_model(config_path(SEGFORMER_RAW), TINY)
    base = count_flops(model, 9, (32, 64))
    model.data_preprocessor.enhancer = Untraceable()
    flops = count_flops(model, 9, (32, 64))
    assert flops['total'] is None and flops['enhancer'] is None
    assert 'Untraceable cannot be traced' in flops['note']
    assert 'a custom kernel' in flops['note']
    assert base['note'] is None


def test_parameters_exclude_the_auxiliary_head():
    _, model = build_model(config_path(PSPNET_WGSE), TINY)
    parameters = inference_parameters(model)
    assert parameters['total'] == count(model) - count(model.auxiliary_head)
    assert parameters['enhancer'] == count(model.data_preprocessor.enhancer)


def test_train_step_time_and_peak_memory():
    cfg, model = build_model(config_path(SEGFORMER_RAW), TINY)
    before = [p.detach().clone() for p in model.parameters()]
    train = measure_train_step(model, cfg.optim_wrapper, 9, (32, 64),
                               batch_size=2, repeat=2, warmup=1)
    assert len(train['step_ms']['samples']) == 2
    assert train['step_ms']['median'] > 0
    memory = train['memory']
    assert memory['kind'] in ('cpu_peak_rss', 'cpu_peak_rss_process_lifetime')
    assert memory['peak_mb'] >= memory['baseline_mb'] > 0
    assert any(not torch.equal(a, p) for a, p in zip(before,
                                                     model.parameters()))
    assert measure_enhancer_step(model, 9, (32, 64), 2, 1, 0) is None


def test_markdown_table_aligns_numbers_right():
    table = markdown_table(['name', 'ms'], [['a', '1.5 ± 0.1'],
                                            ['bb', '12.0 ± 2.0']])
    lines = table.splitlines()
    assert lines[0] == '| name |         ms |'
    assert lines[1] == '|------|-----------:|'
    assert lines[2] == '| a    |  1.5 ± 0.1 |'


def test_markdown_table_keeps_any_text_in_its_cell():
    """The first GPU report's autotune keys ('NVIDIA H200 | band_forward |
    ...') split their rows into six columns of a three-column table."""
    table = markdown_table(['key', 'n'], [['GPU | kernel', 16],
                                          ['two\nlines', 4]])
    lines = table.splitlines()
    assert lines[2] == r'| GPU \| kernel | 16 |'
    assert lines[3] == '| two lines     |  4 |'
    # every row has the header's cells (an escaped bar is not a border)
    assert {line.replace(r'\|', '').count('|') for line in lines} == {3}
