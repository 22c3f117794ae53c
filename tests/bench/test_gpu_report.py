"""dev/gpu_report.py: the one-command GPU report, dry-run on the CPU at tiny
shapes (``--dry-run``: Triton in its interpreter), stopped by its time
budget and resumed, so that the first GPU session does not fail on a bug
in the script; failures are recorded, not fatal; the targets are judged
right; Nsight Compute's output and the predictor's answer are read
right."""
import json
import os.path as osp
import re
import subprocess
import sys

import pytest
import torch

from wgse_bench.gpu_report import kernels, measure, render, sections, targets
from wgse_mmseg.core.wgse import first_use_check, triton_launch_choices

pytest.importorskip('pytorch_wavelets')
ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SECTIONS = {'ceilings', 'band_kernels', 'wgse', 'first_use', 'stalls',
            'tensor_cores', 'profile', 'correctness', 'segmentation',
            'latency', 'paper', 'targets'}


@pytest.fixture(scope='module')
def goals(load_tool):
    return load_tool('dev/gpu_report.py').TARGETS


def _check_dry_run(report, goals):
    """What a finished dry run's report holds, section by section."""
    assert set(report['sections']) == SECTIONS
    assert all(s['status'] == 'ok' for s in report['sections'].values())
    env = report['environment']
    assert env['device'] == 'cpu' and env['triton_interpreter'] is True
    found = report['sections']

    # the ceilings: a copy and a product measured, no GPU clocks
    assert found['ceilings']['copy']['tb_per_s'] > 0
    assert found['ceilings']['matmul_bf16']['tflops'] > 0
    assert 'no GPU clocks' in found['ceilings']['clocks_idle']['note']

    # both band kernels timed, no predictor yet: said so, not invented
    rows = found['band_kernels']['rows']
    assert [(r['kernel'], r['precision']) for r in rows] == [
        ('band_forward', 'tf32'), ('band_backward', 'tf32')]
    for row in rows:
        assert row['min_ms'] <= row['median_ms'] <= row['max_ms']
        assert row['predicted_ms'] is None
        assert row['prediction_note'].startswith('no prediction')

    # the pass: the reference and every backend, ratios to the reference
    passes = {r['impl']: r for r in found['wgse']['rows']}
    assert {'reference', 'torch', 'triton'} <= set(passes)
    assert passes['triton']['backend'] == 'triton'
    for row in passes.values():
        assert row['time_vs_reference'] == pytest.approx(
            row['median_ms'] / passes['reference']['median_ms'])

    # the first-use check, as 'auto' would run it, at every precision
    checks = {r['precision']: r for r in found['first_use']['rows']}
    assert set(checks) == set(measure.PRECISIONS)
    assert checks['bf16']['passed'] is checks['tf32']['passed'] is None
    row = checks['ieee']
    assert row['passed'] is True and row['auto_runs'] == 'triton'
    assert 0 <= row['max_error'] <= row['tolerance'] == \
        first_use_check.TOLERANCE

    # no ncu on the CPU: torch's profiler's times, and the reason
    stalls = found['stalls']
    assert stalls['tool'] == 'torch.profiler'
    assert 'Nsight Compute profiles CUDA' in stalls['note']
    assert [(r['kernel'], r['stalls']) for r in stalls['rows']] == [
        ('band_forward', None), ('band_backward', None)]
    assert all(r['ms'] > 0 for r in stalls['rows'])

    # the tensor-core loops at both tiles: TF32's products right, the
    # interpreter's bf16 (raw 16-bit integers) measured, not judged
    cores = {(r['kernel'], r['precision']): r
             for r in found['tensor_cores']['rows']}
    assert {(k, r['block']) for (k, _), r in cores.items()} == {
        ('band_forward', triton_launch_choices.FORWARD_CONFIGS[0].block),
        ('band_backward',
         triton_launch_choices.backward_configs(False, 'tf32')[0].block)}
    for (kernel, precision), row in cores.items():
        assert row['instruction'] == 'interpreted'
        assert row['of_matmul'] == pytest.approx(
            row['tflops'] / found['ceilings']['matmul_bf16']['tflops'])
        if precision == 'tf32':
            assert row['max_rel_error'] < 1e-5

    assert 'needs a GPU' in found['profile']['note']
    rows = {(r['backend'], r['precision']): r
            for r in found['correctness']['rows']}
    assert rows[('triton', 'ieee')]['ok'] is rows[('torch', 'ieee')]['ok'] \
        is True
    assert rows[('torch', 'bf16')]['note'] == measure.REDUCED_PRECISION_NOTE

    steps = found['segmentation']['rows']
    assert [(r['model'], r['enhancer']) for r in steps] == [
        (m, e) for m in sections.MODELS for e in ('raw', 'WGSE')]
    for raw, with_wgse in (steps[:2], steps[2:]):
        assert with_wgse['step_vs_raw'] == pytest.approx(
            with_wgse['step_ms']['median'] / raw['step_ms']['median'])
    assert [r['enhancer'] for r in found['paper']['rows']] == ['raw', 'WGSE']
    # every figure but the GPU's own: CUDA memory, bf16 (timed on a GPU
    # alone) and AMP
    measured = {key: t['value'] is not None for key, t in zip(
        goals, found['targets']['rows'])}
    assert measured == {key: key not in ('wgse_gib', 'wgse_bf16_ms',
                                         'step_ratio_amp')
                        for key in goals}


@pytest.mark.long(60)
def test_a_dry_run_stopped_by_its_budget_resumes(tmp_path, goals, load_tool,
                                                 single_thread, capsys,
                                                 monkeypatch):
    """The tool's ``main`` in this process (Triton interpreted, as
    ``--dry-run`` sets it): the budget spent once the band kernels are
    timed (the clock made to say so), the rest is left to ``--resume``,
    which measures only that; together, every section's code ran once."""
    tool = load_tool('dev/gpu_report.py')
    args = ['--dry-run', '--out-dir', str(tmp_path)]
    spent = []

    def band_kernels_then_spent(run, measure_step=sections.STEPS[1].measure):
        found = measure_step(run)
        spent.append(True)
        return found

    assert sections.STEPS[1].names == ('band_kernels', )
    monkeypatch.setattr(sections, 'STEPS', (sections.STEPS[0], sections.STEPS[
        1]._replace(measure=band_kernels_then_spent)) + sections.STEPS[2:])
    monkeypatch.setattr(sections.Clock, 'elapsed',
                        lambda self: 100.0 if spent else 0.0)
    assert tool.main(args + ['--budget', '50']) == 1
    report = json.loads((tmp_path / 'gpu.json').read_text())
    statuses = {n: s['status'] for n, s in report['sections'].items()}
    assert statuses == dict({n: 'not run' for n in SECTIONS}, targets='ok',
                            ceilings='ok', band_kernels='ok')
    assert 'time budget (50 s)' in report['sections']['paper']['note']
    assert '[gpu_report' in capsys.readouterr().out  # progress lines

    monkeypatch.undo()
    assert tool.main(args + ['--resume']) == 0
    assert 'kept from the earlier report: ceilings, band_kernels' in \
        capsys.readouterr().out
    report = json.loads((tmp_path / 'gpu.json').read_text())
    assert report['kept'] == ['ceilings', 'band_kernels']
    _check_dry_run(report, goals)

    markdown = (tmp_path / 'gpu.md').read_text()
    assert markdown.startswith('# WGSE on cpu')
    assert '**Not a GPU run**' in markdown and '**Not run**' not in markdown
    for heading, _ in render._SECTION_TEXT.values():
        assert f'## {heading}' in markdown
    assert re.search(r"\| WGSE, backend='triton' +\| tf32 ", markdown)
    assert markdown.count('| PSPNet R50-D8 | WGSE ') == 3  # steps, b1, paper


def test_a_dry_run_never_writes_docs(load_tool, capsys):
    tool = load_tool('dev/gpu_report.py')
    for args, expected in (
            (['--out-dir', osp.join(ROOT, 'docs')], 'docs/ holds the last'),
            (['--resume'], 'needs the --out-dir')):
        with pytest.raises(SystemExit):
            tool.main(['--dry-run'] + args)
        assert expected in capsys.readouterr().err


def test_a_backend_that_raises_is_a_row_and_the_others_run(monkeypatch):
    """One raise (Triton's first-use check at TF32, say) is one row of the
    correctness section, not the whole section lost."""
    original = measure.output_and_grads

    def triton_raises(model, spikes, precision):
        if model.backend == 'triton' and precision == 'ieee':
            raise first_use_check.FirstUseCheckFailed('planted')
        return original(model, spikes, precision)

    monkeypatch.setattr(measure, 'output_and_grads', triton_raises)
    rows = measure.check_correctness((1, 12, 2, 3), 'cpu')['rows']
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
    """The TF32 setting covers the forward and the backward pass (the
    'torch' backend recomputes its forward there); autocast, as in
    training, the forward alone."""

    class Model(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.weight = torch.nn.Parameter(torch.ones(3))

        def forward(self, x):
            return _RecordsPrecision.apply(x * self.weight)

    _RecordsPrecision.seen.clear()
    default = torch.backends.cudnn.allow_tf32
    out, grad = measure.output_and_grads(Model(), torch.ones(3), precision)
    assert _RecordsPrecision.seen == [('forward', tf32, autocast),
                                      ('backward', tf32, False)]
    # the loss's weights, -1 to 1; fp16's loss scale divided out again
    assert torch.equal(grad, torch.tensor([-1.0, 0.0, 1.0]))
    assert torch.backends.cudnn.allow_tf32 is default


def _run(plan=sections.DRY_RUN):
    return sections.Run(plan, sections.Clock(), ROOT, sections.MODELS, {},
                        {}, {})


def test_a_failing_job_is_recorded_and_the_others_run():
    models = {'missing': ('configs/no_such_raw.py', 'configs/no_such.py')}
    rows = sections.model_rows(_run(), (2, 12, 32, 32), True, models)
    assert [r['status'] for r in rows] == ['failed', 'failed']
    assert 'no_such_raw.py' in rows[0]['error']
    assert 'step_vs_raw' not in rows[1]
    assert render.model_table(rows, latency=True).count('| failed: ') == 2


def test_a_section_that_failed_whole_is_rendered_as_its_error():
    report = dict(environment=dict(device='cpu', cpu='x'), seconds=1.0,
                  sections={n: dict(status='ok', rows=[]) for n in SECTIONS})
    report['sections']['ceilings'] = dict(status='failed',
                                          error='RuntimeError: planted')
    report['sections']['stalls'] = dict(sections.NOT_RUN)
    markdown = render.format_report(report, 'python dev/gpu_report.py')
    assert '**Failed**: `RuntimeError: planted`' in markdown
    assert markdown.count('**Not run**') == 1


def _pass(impl, precision, median_ms, peak_mib=None):
    return dict(impl=impl, precision=precision, status='ok',
                median_ms=median_ms, peak_mib=peak_mib)


def test_targets_by_hand(goals):
    found = dict(
        wgse=dict(rows=[_pass('reference', 'tf32', 1000.0, 40000),
                        _pass('torch', 'tf32', 100.0, 5000),
                        _pass('triton', 'tf32', 12.0, 4096),
                        _pass('torch', 'bf16', 90.0),
                        _pass('triton', 'bf16', 9.5, 2048)]),
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
    judged = dict(zip(goals, targets.judge(found, goals)))
    assert judged['wgse_ms']['value'] == 12  # Triton's, TF32
    assert judged['wgse_ms']['met'] and not judged['wgse_ms']['moonshot_met']
    assert judged['wgse_bf16_ms']['value'] == 9.5
    assert judged['wgse_gib']['value'] == 4 and \
        judged['wgse_gib']['met'] is False  # 4 GiB > 1.5
    assert judged['step_ratio']['met'] and \
        not judged['step_ratio']['moonshot_met']  # 1.25: <= 1.3, > 1.15
    assert judged['step_ratio_amp']['moonshot_met']  # 1.1 <= 1.15
    assert judged['segformer_step_ratio']['met'] is False  # 1.6 > 1.5
    assert judged['added_latency_ms']['met'] is False  # 3.5 ms > 3
    assert judged['paper_gb']['value'] == pytest.approx(20000 * 2**20 / 1e9)
    assert judged['paper_memory_ratio']['met']  # 1.11 <= 1.2
    assert judged['first_use_s']['value'] == 31.5
    assert judged['first_use_s']['met'] is False


def test_targets_not_measured_when_their_jobs_failed(goals):
    failed = dict(status='failed', error='RuntimeError: CUDA out of memory')
    found = dict(
        wgse=dict(rows=[dict(failed, impl='triton', precision='tf32')]),
        segmentation=dict(rows=[dict(failed, model='PSPNet R50-D8',
                                     enhancer='WGSE')]),
        paper=dict(rows=[dict(failed, enhancer='WGSE')]))
    assert all(t['value'] is None and t['met'] is None
               for t in targets.judge(found, goals))


@pytest.fixture
def fake_steps(monkeypatch):
    """The report's steps measured by stand-ins that note their calls
    (what a stopped and resumed run measures, in a second)."""
    calls = []

    def stand_in(names):
        def measure_step(run):
            calls.append(names[0])
            return {n: dict(status='ok', rows=[]) for n in names}
        return measure_step

    monkeypatch.setattr(sections, 'STEPS', tuple(
        step._replace(measure=stand_in(step.names))
        for step in sections.STEPS))
    return calls


def test_a_stopped_run_leaves_its_sections_and_resumes(
        tmp_path, monkeypatch, load_tool, fake_steps, capsys):
    """A run a time limit kills (here in the pass) has written the sections
    it finished and marked the others; ``--resume`` measures only those."""
    tool = load_tool('dev/gpu_report.py')
    steps = sections.STEPS

    def time_limit(run):
        raise KeyboardInterrupt('the time limit')

    monkeypatch.setattr(sections, 'STEPS', tuple(
        step._replace(measure=time_limit) if step.names == ('wgse', )
        else step for step in steps))
    args = ['--dry-run', '--out-dir', str(tmp_path)]
    with pytest.raises(KeyboardInterrupt):
        tool.main(args)
    report = json.loads((tmp_path / 'gpu.json').read_text())
    finished = {n for n, s in report['sections'].items()
                if s['status'] == 'ok'}
    assert finished == {'ceilings', 'band_kernels', 'targets'}
    assert (tmp_path / 'gpu.md').read_text().count('**Not run**') == 9
    assert sorted(p.name for p in tmp_path.iterdir()) == ['gpu.json',
                                                          'gpu.md']

    monkeypatch.setattr(sections, 'STEPS', steps)
    del fake_steps[:]
    assert tool.main(args + ['--resume']) == 0
    assert fake_steps == ['wgse', 'first_use', 'stalls', 'tensor_cores',
                          'profile', 'correctness', 'segmentation', 'paper']
    assert 'Kept from an earlier run' in (tmp_path / 'gpu.md').read_text()

    # without --resume, or where the code changed, all is measured again
    del fake_steps[:]
    assert tool.main(args) == 0
    assert len(fake_steps) == len(steps)
    del fake_steps[:]
    monkeypatch.setattr(sections, 'code_digest', lambda root: 'changed')
    assert tool.main(args + ['--resume']) == 0
    assert len(fake_steps) == len(steps)
    assert 'environment differ from this run' in capsys.readouterr().out


def test_the_budget_leaves_what_does_not_fit(monkeypatch, fake_steps):
    """After the first step (which always runs), a step starts only where
    the time so far leaves room; what does not fit is left to --resume."""
    monkeypatch.setattr(sections.Clock, 'elapsed', lambda self: 10.0)
    report = sections.run_report(sections.DRY_RUN, ROOT, {}, budget_s=5)
    assert fake_steps == ['ceilings']
    left = [n for n, s in report['sections'].items()
            if s['status'] == 'not run']
    assert left == list(sections.SECTIONS[1:-1])
    assert 'the time budget (5 s) left no room' in \
        report['sections']['wgse']['note']
    del fake_steps[:]
    sections.run_report(sections.DRY_RUN, ROOT, {}, budget_s=11)
    assert len(fake_steps) == len(sections.STEPS)


def test_what_a_resumed_report_keeps():
    env = sections.environment('cpu', ROOT)
    plan = sections.DRY_RUN
    ok, failed = dict(status='ok', rows=[]), dict(status='failed', error='x')
    earlier = json.loads(json.dumps(dict(
        plan=plan._asdict(), environment=dict(env, load_average=9.0),
        sections=dict(ceilings=ok, first_use=failed, wgse=ok,
                      targets=ok))))
    assert sections.kept_sections(earlier, plan, env)[0] == [
        'ceilings', 'wgse']  # finished ones; targets are recomputed
    for changed in (dict(earlier, plan=dict(earlier['plan'], repeat=2)),
                    dict(earlier, environment=dict(env, torch='other')),
                    dict(earlier, environment=dict(env, code='other'))):
        kept, why = sections.kept_sections(changed, plan, env)
        assert kept == [] and 'differ' in why
    assert sections.kept_sections(None, plan, env)[0] == []
    # a file's odd content keeps nothing rather than failing
    assert sections.kept_sections(dict(earlier, sections=[1]), plan,
                                  env)[0] == []


def test_the_code_digest_follows_the_code(tmp_path):
    for top in sections.CODE:
        (tmp_path / top).mkdir()
        (tmp_path / top / 'a.py').write_text('x = 1\n')
    first = sections.code_digest(str(tmp_path))
    (tmp_path / 'configs' / 'notes.txt').write_text('not code')
    assert sections.code_digest(str(tmp_path)) == first
    (tmp_path / 'configs' / 'a.py').write_text('x = 2\n')
    assert sections.code_digest(str(tmp_path)) != first


@pytest.mark.parametrize('content, expected', [
    (b'{"plan": ', 'cannot be read as a report'),
    (b'[1, 2]', 'holds no report'),
])
def test_resume_from_a_file_that_is_no_report(tmp_path, load_tool, content,
                                              expected):
    (tmp_path / 'gpu.json').write_bytes(content)
    tool = load_tool('dev/gpu_report.py')
    with pytest.raises(SystemExit, match=expected) as error:
        tool.main(['--dry-run', '--out-dir', str(tmp_path), '--resume'])
    assert str(tmp_path / 'gpu.json') in str(error.value)


#: Nsight Compute's ``--csv --page raw`` output as it prints it: its own
#: lines, the program's, a header, the units, a row a launch
NCU_OUTPUT = '''==PROF== Connected to process 12 (python3)
==PROF== Profiling "band_forward": 0%....50%....100% - 9 passes
"ID","Process ID","Kernel Name","gpu__time_duration.sum",\
"smsp__issue_active.avg.pct_of_peak_sustained_active",\
"smsp__average_warps_issue_stalled_long_scoreboard_per_issue_active.ratio",\
"smsp__average_warps_issue_stalled_barrier_per_issue_active.ratio"
"","","","usecond","%","",""
"0","12","band_forward","1,250.50","31.5","2.25","0.5"
"1","12","band_backward","48,100","12","0.75","n/a"
==PROF== Disconnected from process 12
'''


def test_nsight_computes_rows_are_read():
    rows = kernels.parse_ncu_csv(NCU_OUTPUT)
    assert rows == [
        dict(kernel='band_forward', ms=1.2505, issue_active_pct=31.5,
             sm_throughput_pct=None,
             stalls=dict(long_scoreboard=2.25, barrier=0.5)),
        dict(kernel='band_backward', ms=48.1, issue_active_pct=12.0,
             sm_throughput_pct=None, stalls=dict(long_scoreboard=0.75))]
    assert kernels.parse_ncu_csv('==PROF== no kernels were profiled') == []


@pytest.mark.parametrize('answer, expected', [
    (dict(band_forward=2.0, band_backward=dict(predicted_ms=5.0)),
     dict(band_forward=2.0, band_backward=5.0)),
    ([dict(kernel='band_forward', precision='tf32', predicted_ms=2.0),
      dict(kernel='band_forward', precision='bf16', predicted_ms=1.0),
      dict(kernel='pass', predicted_ms=9.0)],
     {'band_forward': 2.0, 'pass': 9.0}),
    ('a sentence', {}),
])
def test_the_prediction_is_read_through_one_adapter(monkeypatch, answer,
                                                    expected):
    from wgse_bench import kernel_prediction
    calls = []

    def predict(**call):
        calls.append(call)
        return answer

    monkeypatch.setattr(kernel_prediction, 'predict_band_kernels', predict,
                        raising=False)
    found = kernels.predictions(dict(gpu='H200'), [4, 129, 8, 8], 'tf32')
    assert found['kernels'] == expected
    assert calls == [dict(environment=dict(gpu='H200'),
                          shape=(4, 129, 8, 8), precision='tf32')]
    assert (found['note'] is None) == bool(expected)


def test_no_predictor_is_no_prediction(monkeypatch):
    from wgse_bench import kernel_prediction
    monkeypatch.delattr(kernel_prediction, 'predict_band_kernels',
                        raising=False)
    assert kernels.predictions({}, [1, 12, 3, 4], 'tf32') == dict(
        kernels={}, note='no prediction: wgse_bench.kernel_prediction has '
        'no predict_band_kernels')

    def broken(**call):
        raise KeyError('sms')

    monkeypatch.setattr(kernel_prediction, 'predict_band_kernels', broken,
                        raising=False)
    note = kernels.predictions({}, [1, 12, 3, 4], 'tf32')['note']
    assert note.startswith('no prediction') and "KeyError: 'sms'" in note


#: compiles the tensor-core loop at each band kernel's TF32 tile for sm_90
#: (no GPU needed) and prints the instruction each compiled to
COMPILE_FOR_HOPPER = '''
import json
import triton
from triton.backends.compiler import GPUTarget
from triton.compiler import ASTSource
from wgse_bench.gpu_report import ceilings
from wgse_mmseg.core.wgse import triton_launch_choices as choices
found = {}
for kernel, entry in (('band_forward', choices.FORWARD_CONFIGS[0]),
                      ('band_backward', choices.backward_configs(False,
                                                                 'tf32')[0])):
    constants = dict(ITERATIONS=64, M=entry.block, N=32, K=32,
                     PRECISION='tf32')
    signature = dict(a_ptr='*fp32', b_ptr='*fp32', out_ptr='*fp32',
                     **{name: 'constexpr' for name in constants})
    compiled = triton.compile(
        ASTSource(fn=ceilings._dot_loop, signature=signature,
                  constexprs=constants), target=GPUTarget('cuda', 90, 32),
        options=dict(num_warps=entry.num_warps))
    found[kernel] = ceilings._instruction(compiled)
print(json.dumps(found))
'''


@pytest.mark.gpu_targets
@pytest.mark.needs_triton
@pytest.mark.long(30)
def test_the_tensor_core_loops_run_the_instructions_they_measure(
        without_openmmlab):
    """On Hopper the forward's 128-pixel tile compiles to wgmma and the
    backward's 32-pixel tile to mma.sync, as the section's rows say: read
    from the PTX triton compiles for sm_90 here, without a GPU."""
    proc = subprocess.run([sys.executable, '-c', COMPILE_FOR_HOPPER],
                          capture_output=True, text=True,
                          env=without_openmmlab, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == dict(
        band_forward='wgmma', band_backward='mma.sync')


def test_the_predictor_is_asked_once_a_run_and_precision(monkeypatch):
    """The band kernels' and the pass's rows read one answer (a predictor
    may compile the kernels to answer)."""
    from wgse_bench import kernel_prediction
    calls = []

    def predict(**call):
        calls.append(call['precision'])
        return dict(band_forward=1.0)

    monkeypatch.setattr(kernel_prediction, 'predict_band_kernels', predict,
                        raising=False)
    run = _run()
    assert [run.prediction(p)['kernels'] for p in ('tf32', 'tf32', 'bf16')
            ] == [dict(band_forward=1.0)] * 3
    assert calls == ['tf32', 'bf16']
