"""dev/gpu_report.py: the one-command GPU report, run on the
CPU at tiny shapes (``--smoke``: Triton in its interpreter), so that the first
GPU run does not fail on a bug in the script; failures are recorded, not
fatal; the targets are judged right."""
import json
import os.path as osp

import pytest
import torch

from wgse_bench import gpu_report
from wgse_mmseg.core.wgse import first_use_check, triton_band_networks

pytest.importorskip('pytorch_wavelets')
ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SECTIONS = {'correctness', 'first_use', 'wgse', 'profile', 'segmentation',
            'latency', 'paper', 'targets'}


@pytest.fixture(scope='module')
def targets(load_tool):
    return load_tool('dev/gpu_report.py').TARGETS


@pytest.mark.long(45)
def test_smoke_run_writes_every_section(tmp_path, targets, load_tool,
                                        single_thread, capsys):
    """The tool's ``main`` in this process (Triton interpreted here, as
    ``--smoke`` sets it; its benchmark workers are processes of their
    own)."""
    tool = load_tool('dev/gpu_report.py')
    assert tool.main(['--smoke', '--out-dir', str(tmp_path)]) == 0
    assert '[gpu_report' in capsys.readouterr().out  # progress lines
    report = json.loads((tmp_path / 'gpu.json').read_text())
    assert set(report['sections']) == SECTIONS
    assert all(s['status'] == 'ok' for s in report['sections'].values())
    env = report['environment']
    assert env['device'] == 'cpu' and env['triton_interpreter'] is True
    assert env['torch'] and env['triton'] != 'not installed'
    sections = report['sections']

    # both backends at every precision; Triton's bf16 cannot run in the
    # interpreter, and its tf32 would repeat the ieee arithmetic: both say
    # so; the torch backend's reduced precisions are measured, not judged
    rows = {(r['backend'], r['precision']): r
            for r in sections['correctness']['rows']}
    assert set(rows) == {(b, p) for b in ('triton', 'torch')
                         for p in gpu_report.PRECISIONS}
    for (backend, precision), row in rows.items():
        if precision == 'ieee':
            assert row['ok'] is True
            assert row['max_rel_error'] <= row['tolerance'] == \
                triton_band_networks.TOLERANCES['ieee']
        elif backend == 'triton':
            assert row['ok'] is None and 'interpreter' in row['note']
        else:
            assert row['ok'] is None and row['tolerance'] is None
            assert row['note'] == gpu_report.REDUCED_PRECISION_NOTE
            assert row['max_rel_error'] < 1e-2  # float32 on the CPU

    # the profile is a GPU's: on the CPU the section says so
    assert 'needs a GPU' in sections['profile']['note']
    assert not sections['profile']['rows']

    # the first-use check, as 'auto' would run it, at every precision
    checks = {r['precision']: r for r in sections['first_use']['rows']}
    assert set(checks) == set(gpu_report.PRECISIONS)
    assert checks['bf16']['passed'] is checks['tf32']['passed'] is None
    assert 'interpreter' in checks['tf32']['note']
    assert checks['fp16']['passed'] is None
    row = checks['ieee']
    assert row['passed'] is True and row['auto_runs'] == 'triton'
    assert row['device'] == 'cpu' and row['backend'] == 'triton'
    assert 0 <= row['max_error'] <= row['tolerance'] == \
        first_use_check.TOLERANCE

    wgse = {r['impl']: r for r in sections['wgse']['rows']}
    assert {'reference', 'torch', 'triton'} <= set(wgse)
    assert wgse['triton']['backend'] == 'triton'
    assert wgse['reference']['time_vs_reference'] == 1
    for row in wgse.values():
        assert row['median_s'] > 0
        assert row['time_vs_reference'] == pytest.approx(
            row['median_s'] / wgse['reference']['median_s'])

    steps = sections['segmentation']['rows']
    assert [(r['model'], r['enhancer']) for r in steps] == [
        (m, e) for m in gpu_report.MODELS for e in ('raw', 'WGSE')]
    for raw, with_wgse in (steps[:2], steps[2:]):
        assert raw['enhancer_backend'] is None
        assert with_wgse['enhancer_backend'] in ('compiled', 'torch')
        assert with_wgse['step_vs_raw'] == pytest.approx(
            with_wgse['step_ms']['median'] / raw['step_ms']['median'])
        assert with_wgse['added_latency_ms'] == pytest.approx(
            with_wgse['latency_ms']['median'] -
            raw['latency_ms']['median'])
    assert [r['enhancer'] for r in sections['paper']['rows']] == \
        ['raw', 'WGSE']
    assert sections['paper']['shape'] == list(gpu_report.SMOKE.paper_shape)
    assert len(sections['targets']['rows']) == len(targets)
    # every figure but the GPU's own: the profiled bf16 pass and AMP
    measured = {key: t['value'] is not None for key, t in zip(
        targets, sections['targets']['rows'])}
    assert measured == {key: key not in ('wgse_bf16_ms', 'step_ratio_amp')
                        for key in targets}

    markdown = (tmp_path / 'gpu.md').read_text()
    assert markdown.startswith('# WGSE on cpu')
    assert '**Not a GPU run**' in markdown
    for heading in ('## Correctness against float64',
                    '## WGSE forward+backward', '## Training steps',
                    '## Latency at batch 1', "## The paper's shape",
                    '## Against the targets',
                    '## First-use check'):
        assert heading in markdown
    assert "| WGSE, backend='triton'" in markdown
    assert markdown.count('| PSPNet R50-D8 | WGSE ') == 3  # steps, b1, paper


def test_a_backend_that_raises_is_a_row_and_the_others_run(monkeypatch):
    """The first GPU run lost the whole correctness section to one raise
    (Triton's first-use check at TF32); now that is one row of it."""
    measure = gpu_report._output_and_grads

    def triton_raises(model, spikes, precision):
        if model.backend == 'triton' and precision == 'ieee':
            raise first_use_check.FirstUseCheckFailed('planted')
        return measure(model, spikes, precision)

    monkeypatch.setattr(gpu_report, '_output_and_grads', triton_raises)
    rows = gpu_report.check_correctness((1, 12, 2, 3), 'cpu')['rows']
    failed = [r for r in rows if r['ok'] is False]
    assert [(r['backend'], r['precision']) for r in failed] == [
        ('triton', 'ieee')]
    assert failed[0]['error'] == 'FirstUseCheckFailed: planted'
    assert [r['ok'] for r in rows if r['backend'] == 'torch'] == [
        True, None, None, None]


class _RecordsPrecision(torch.autograd.Function):
    """Identity; notes the TF32 and autocast settings each pass meets."""

    seen = []

    @staticmethod
    def forward(ctx, x):
        _RecordsPrecision.seen.append(
            ('forward', torch.backends.cudnn.allow_tf32,
             torch.is_autocast_enabled('cpu')))
        return x.clone()

    @staticmethod
    def backward(ctx, grad):
        _RecordsPrecision.seen.append(
            ('backward', torch.backends.cudnn.allow_tf32,
             torch.is_autocast_enabled('cpu')))
        return grad


@pytest.mark.parametrize('precision, tf32, autocast', [
    ('ieee', False, False), ('tf32', True, False), ('bf16', False, True),
    ('fp16', False, True)])
def test_a_precision_holds_for_both_passes(precision, tf32, autocast):
    """The second GPU run measured the torch backend at 'ieee' with TF32
    errors: its backward ran after the precision's block, under torch's
    default TF32, and recomputed the forward there. The TF32 setting now
    covers both passes; autocast, as in training, the forward alone."""

    class Model(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.weight = torch.nn.Parameter(torch.ones(3))

        def forward(self, x):
            return _RecordsPrecision.apply(x * self.weight)

    _RecordsPrecision.seen.clear()
    default = torch.backends.cudnn.allow_tf32
    out, grad = gpu_report._output_and_grads(Model(), torch.ones(3),
                                             precision)
    assert _RecordsPrecision.seen == [('forward', tf32, autocast),
                                      ('backward', tf32, False)]
    # the loss's weights, -1 to 1; fp16's loss scale divided out again
    assert torch.equal(grad, torch.tensor([-1.0, 0.0, 1.0]))
    assert torch.backends.cudnn.allow_tf32 is default


def test_a_failing_job_is_recorded_and_the_others_run(tmp_path):
    models = {'missing': ('configs/no_such_raw.py', 'configs/no_such.py')}
    rows = gpu_report._model_rows(gpu_report.SMOKE, gpu_report._Clock(),
                                  (2, 12, 32, 32), True, models, ROOT)
    assert [r['status'] for r in rows] == ['failed', 'failed']
    assert 'no_such_raw.py' in rows[0]['error']
    assert 'step_vs_raw' not in rows[1]
    table = gpu_report._model_table(rows, latency=True)
    assert table.count('| failed: ') == 2


def _row(impl, median_s, peak_mib):
    return dict(impl=impl, status='ok', median_s=median_s,
                peak_mib=peak_mib)


def test_targets_by_hand(targets):
    sections = dict(
        wgse=dict(rows=[_row('reference', 1.0, 40000),
                        _row('torch', 0.1, 5000),
                        _row('triton', 0.012, 4096)]),
        profile=dict(rows=[dict(status='ok', precision='bf16',
                                span_ms=9.5)]),
        first_use=dict(rows=[dict(seconds=12.0), dict(seconds=31.5),
                             dict(passed=None, note='not run')]),
        segmentation=dict(rows=[
            dict(model='PSPNet R50-D8', enhancer='raw', status='ok'),
            dict(model='PSPNet R50-D8', enhancer='WGSE', status='ok',
                 step_vs_raw=1.25, added_latency_ms=3.5),
            dict(model='SegFormer-B0', enhancer='WGSE', status='ok',
                 step_vs_raw=1.6),
            dict(model='PSPNet R50-D8', enhancer='WGSE, AMP', status='ok',
                 step_vs_raw=1.1)]),
        paper=dict(rows=[dict(enhancer='raw', status='ok',
                              memory=dict(peak_mb=18000)),
                         dict(enhancer='WGSE', status='ok',
                              memory=dict(peak_mb=20000),
                              memory_vs_raw=20000 / 18000)]))
    found = {key: t for key, t in zip(
        targets, gpu_report._targets(sections, targets))}
    assert found['wgse_ms']['value'] == pytest.approx(12)  # Triton's, ms
    assert found['wgse_ms']['met'] and not found['wgse_ms']['moonshot_met']
    assert found['wgse_bf16_ms']['value'] == 9.5
    assert found['wgse_gib']['value'] == 4 and \
        found['wgse_gib']['met'] is False  # 4 GiB > 1.5
    assert found['step_ratio']['met'] and \
        not found['step_ratio']['moonshot_met']  # 1.25: <= 1.3, > 1.15
    assert found['step_ratio_amp']['moonshot_met']  # 1.1 <= 1.15
    assert found['segformer_step_ratio']['met'] is False  # 1.6 > 1.5
    assert found['added_latency_ms']['met'] is False  # 3.5 ms > 3
    assert found['paper_gb']['value'] == pytest.approx(20000 * 2**20 / 1e9)
    assert found['paper_memory_ratio']['met']  # 1.11 <= 1.2
    assert found['first_use_s']['value'] == 31.5
    assert found['first_use_s']['met'] is False


def test_targets_not_measured_when_their_jobs_failed(targets):
    failed = dict(status='failed', error='RuntimeError: CUDA out of memory')
    sections = dict(
        wgse=dict(rows=[dict(failed, impl='triton')]),
        segmentation=dict(rows=[dict(failed, model='PSPNet R50-D8',
                                     enhancer='WGSE')]),
        paper=dict(rows=[dict(failed, enhancer='WGSE')]))
    assert all(t['value'] is None and t['met'] is None
               for t in gpu_report._targets(sections, targets))


@pytest.fixture
def fake_sections(monkeypatch):
    """The report's sections measured by stand-ins that note their calls
    (what a stopped and resumed run measures, in a second)."""
    calls = []

    def stand_in(*names):
        def measure(plan, clock, *args):
            calls.append(names[0])
            section = dict(status='ok', rows=[], shape=[1, 12, 3, 4])
            return section if len(names) == 1 else {n: section
                                                    for n in names}
        return measure

    for function, names in [
            ('_correctness_section', ('correctness', )),
            ('_first_use_section', ('first_use', )),
            ('_wgse_section', ('wgse', )),
            ('_profile_section', ('profile', )),
            ('_segmentation_sections', ('segmentation', 'latency')),
            ('_paper_section', ('paper', ))]:
        monkeypatch.setattr(gpu_report, function, stand_in(*names))
    return calls


def test_a_stopped_run_leaves_its_sections_and_resumes(
        tmp_path, monkeypatch, load_tool, fake_sections, capsys):
    """A run a time limit stops (here at the WGSE section) has written the
    sections it finished and marked the others; ``--resume`` measures only
    those, and the report says which it kept."""
    tool = load_tool('dev/gpu_report.py')
    measure_wgse = gpu_report._wgse_section

    def time_limit(plan, clock):
        raise KeyboardInterrupt('the time limit')

    monkeypatch.setattr(gpu_report, '_wgse_section', time_limit)
    with pytest.raises(KeyboardInterrupt):
        tool.main(['--smoke', '--out-dir', str(tmp_path)])
    report = json.loads((tmp_path / 'gpu.json').read_text())
    statuses = {n: s['status'] for n, s in report['sections'].items()}
    assert statuses == dict(correctness='ok', first_use='ok',
                            wgse='not run', profile='not run',
                            segmentation='not run', latency='not run',
                            paper='not run', targets='ok')
    assert all(t['value'] is None for t in
               report['sections']['targets']['rows'])
    markdown = (tmp_path / 'gpu.md').read_text()
    assert markdown.count('**Not run**') == 5
    assert sorted(p.name for p in tmp_path.iterdir()) == ['gpu.json',
                                                          'gpu.md']

    monkeypatch.setattr(gpu_report, '_wgse_section', measure_wgse)
    del fake_sections[:]
    assert tool.main(['--smoke', '--out-dir', str(tmp_path),
                      '--resume']) == 0
    assert fake_sections == ['wgse', 'profile', 'segmentation', 'paper']
    assert 'kept from the earlier report: correctness, first_use' in \
        capsys.readouterr().out
    report = json.loads((tmp_path / 'gpu.json').read_text())
    assert report['kept'] == ['correctness', 'first_use']
    assert {s['status'] for s in report['sections'].values()} == {'ok'}
    assert 'Kept from an earlier run' in (tmp_path / 'gpu.md').read_text()

    # without --resume, or where the code changed, all is measured again
    del fake_sections[:]
    assert tool.main(['--smoke', '--out-dir', str(tmp_path)]) == 0
    assert len(fake_sections) == 6
    del fake_sections[:]
    monkeypatch.setattr(gpu_report, 'code_digest', lambda root: 'changed')
    assert tool.main(['--smoke', '--out-dir', str(tmp_path),
                      '--resume']) == 0
    assert len(fake_sections) == 6
    assert "environment differ from this run" in capsys.readouterr().out


def test_what_a_resumed_report_keeps():
    env = gpu_report.environment('cpu', ROOT)
    plan = gpu_report.SMOKE
    ok, failed = dict(status='ok', rows=[]), dict(status='failed', error='x')
    earlier = json.loads(json.dumps(dict(
        plan=plan._asdict(), environment=dict(env, load_average=9.0),
        sections=dict(correctness=ok, first_use=failed, wgse=ok,
                      targets=ok))))
    assert gpu_report.kept_sections(earlier, plan, env)[0] == [
        'correctness', 'wgse']  # finished ones; targets are recomputed
    for changed in (dict(earlier, plan=dict(earlier['plan'], repeat=2)),
                    dict(earlier, environment=dict(env, torch='other')),
                    dict(earlier, environment=dict(env, code='other'))):
        kept, why = gpu_report.kept_sections(changed, plan, env)
        assert kept == [] and 'differ' in why
    assert gpu_report.kept_sections(None, plan, env)[0] == []
    # a file's odd content keeps nothing rather than failing
    assert gpu_report.kept_sections(dict(earlier, sections=[1]), plan,
                                    env)[0] == []


def test_the_code_digest_follows_the_code(tmp_path):
    for top in gpu_report.CODE:
        (tmp_path / top).mkdir()
        (tmp_path / top / 'a.py').write_text('x = 1\n')
    first = gpu_report.code_digest(str(tmp_path))
    (tmp_path / 'configs' / 'notes.txt').write_text('not code')
    assert gpu_report.code_digest(str(tmp_path)) == first
    (tmp_path / 'configs' / 'a.py').write_text('x = 2\n')
    assert gpu_report.code_digest(str(tmp_path)) != first


@pytest.mark.parametrize('content, expected', [
    (b'{"plan": ', 'cannot be read as a report'),
    (b'[1, 2]', 'holds no report'),
])
def test_resume_from_a_file_that_is_no_report(tmp_path, load_tool, content,
                                              expected):
    (tmp_path / 'gpu.json').write_bytes(content)
    tool = load_tool('dev/gpu_report.py')
    with pytest.raises(SystemExit, match=expected) as error:
        tool.main(['--smoke', '--out-dir', str(tmp_path), '--resume'])
    assert str(tmp_path / 'gpu.json') in str(error.value)
