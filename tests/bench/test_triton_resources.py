"""WGSE's Triton kernels compile for real GPUs (sm_80, sm_89, sm_90, sm_100,
sm_120) with no GPU: every variant the dispatcher can launch, use no local
memory and leave room for two programs per SM (full float32's forward on
sm_100 and sm_120 excepted), and the tensor-core ones stay within the cost
model's instruction budget (``wgse_bench.triton_resources``; the table is in
docs/wgse_speed.md).

The tests that compile are marked ``gpu_targets``: about 2 minutes of CPU,
skipped unless pytest gets ``--gpu-targets`` (``bash tools/run_tests.sh
--gpu-targets -m gpu_targets``, a step of .ci/run of its own); the checks of
the readers by hand run in the suite."""
import ast
import inspect
import json
import os
import subprocess
import textwrap

import pytest

from wgse_bench import kernel_prediction, triton_resources
from wgse_mmseg.core.wgse import triton_band_networks, triton_launch_choices

triton_band_kernels = pytest.importorskip(
    'wgse_mmseg.core.wgse.triton_band_kernels')

pytestmark = pytest.mark.needs_triton


@pytest.fixture(scope='session')
def rows(built_once):
    # once a run, in a fresh process without TRITON_INTERPRET, two compiles
    # side by side (CI's two cores)
    def build(path):
        with open(path, 'w') as f:
            json.dump(triton_resources.compile_all(jobs=2), f)
    with open(built_once('triton_resources.json', build)) as f:
        return json.load(f)


@pytest.mark.gpu_targets
def test_every_launchable_variant_compiles_for_every_target(rows):
    """Forward and backward (with and without the input gradient) at every
    width, precision and launch entry of each target, for sm_80, sm_89,
    sm_90, sm_100 and sm_120."""
    compiled = [(r['arch'], r['kernel'], r['hidden'], r['precision'],
                 r['input_grad'], r['block'], r['num_warps'], r['maxnreg'])
                for r in rows]
    expected = {(a, *v) for v, a in triton_resources.jobs_for(
        triton_resources.ARCHITECTURES)}
    assert len(compiled) == len(set(compiled)) and set(compiled) == expected
    assert {a for a, *_ in compiled} == {'sm_80', 'sm_89', 'sm_90',
                                         'sm_100', 'sm_120'}
    backward = {(r['arch'], r['precision'], r['input_grad'], r['block'])
                for r in rows if r['kernel'] == 'band_backward'}
    # 16 pixels for the input gradient and in full float32, 32 otherwise
    assert {(p, g, b) for _, p, g, b in backward} == {
        (p, g, 16 if g or p == 'ieee' else 32)
        for p in triton_band_networks.TOLERANCES for g in (True, False)}
    assert {(a, p) for a, p, *_ in backward} == {
        (a, p) for a in triton_resources.ARCHITECTURES
        for p in triton_band_networks.TOLERANCES}
    assert all(r['registers'] > 0 and r['programs_per_sm'] >= 1
               for r in rows)


def _names_assigned(statements, input_grad):
    """Names assigned by ``statements`` (the branches under ``if
    INPUT_GRAD:`` only when ``input_grad``)."""
    names = set()
    for statement in statements:
        if isinstance(statement, ast.If) and \
                getattr(statement.test, 'id', None) == 'INPUT_GRAD':
            if input_grad:
                names |= _names_assigned(statement.body, input_grad)
            continue
        for node in ast.walk(statement):
            targets = (node.targets if isinstance(node, ast.Assign) else
                       [node.target] if isinstance(node, ast.AugAssign)
                       else [])
            names |= {n.id for t in targets for n in ast.walk(t)
                      if isinstance(n, ast.Name)}
    return names


def _carried(body, defined, input_grad):
    """The names the ``for`` loops in ``body`` (nested too) carry: per loop,
    those its body assigns that were assigned before it."""
    count = 0
    for statement in body:
        if isinstance(statement, ast.For):
            count += len(_names_assigned(statement.body, input_grad) &
                         defined)
            count += _carried(statement.body, set(defined), input_grad)
        defined |= _names_assigned([statement], input_grad)
    return count


def _loop_variables(kernel, input_grad):
    """How many values a kernel's ``for`` loops must carry from one step to
    the next: the names each assigns that were assigned before it."""
    source = textwrap.dedent(inspect.getsource(
        getattr(triton_band_kernels, kernel).fn))
    return _carried(ast.parse(source).body[0].body, set(), bool(input_grad))


@pytest.mark.gpu_targets
def test_every_loop_variable_is_carried_into_the_next_step(rows):
    """Triton carries a name into the next iteration only if one pass over
    the body changes it: windows that start as one shared tensor
    (``h1_2 = h1_1 = zeros``, then ``h1_2, h1_1 = h1_1, h1_0``) compile to
    a loop in which ``h1_2`` stays zero, which the interpreter never
    shows. Every name the loop reassigns must be carried."""
    for r in rows:
        assert r['loop_carried'] == _loop_variables(
            r['kernel'], r['input_grad']), r


@pytest.mark.parametrize('ttir, carried', [
    ('%r:2 = scf.for %s = %c0 to %c9 step %c1 iter_args(%a = %x, %b = %y)'
     ' -> (f32, f32)  : i32 {', 2),
    ('%r = scf.for %s = %c0 to %c9 step %c1 iter_args(%a = %x) -> (f32)',
     1),
    ('%r:2 = scf.for %t = %c0 to %c9 step %c1 iter_args(%a = %x, %b = %y)'
     ' -> (f32, f32) {\n %q = scf.for %s = %c0 to %c9 step %c1 '
     'iter_args(%c = %a) -> (f32) {', 3),
])
def test_loop_carried_by_hand(ttir, carried):
    assert triton_resources.loop_carried(ttir) == carried


def test_loop_carried_needs_a_loop():
    with pytest.raises(ValueError, match='found none'):
        triton_resources.loop_carried('tt.func @k() { tt.return }')


@pytest.mark.gpu_targets
def test_launched_variants_spill_nothing_and_fit_two_programs(rows):
    """What runs uses no local memory, and two programs of it share an SM:
    every variant on sm_80, sm_89 and sm_90, full float32 (``'ieee'``, on
    the FMA units) included; on sm_100 and sm_120 what runs at TF32, fp16
    and bf16 (full float32's forward spills there: docs/wgse_speed.md)."""
    held = [r for r in rows if r['tensor_cores'] or
            r['arch'] in ('sm_80', 'sm_89', 'sm_90')]
    assert {r['precision'] for r in held} == {'ieee', 'tf32', 'fp16', 'bf16'}
    bad = [r for r in held if r['spill_bytes'] or r['local_bytes']
           or r['programs_per_sm'] < 2]
    assert not bad, triton_resources.format_table(bad)


#: The cost model's budget: the most warp instructions a coefficient
#: position may cost in a kernel's step loop at TF32, fp16 and bf16, and
#: the fewest of them on tensor cores, per kernel and tile, on every target.
#: As compiled by triton 3.6 (docs/wgse_speed.md, "Compiled for GPUs"):
#: forward 9.7-19.8 at 128 pixels, backward 39-70 at 32 and 84-146 at 16;
#: the kernels these replaced took 140 in the backward on sm_90. The fewest
#: tensor-core instructions: 0.12 a position in the forward on sm_100, whose
#: tcgen05 instructions each run a whole 128-row product. A change of the
#: kernels or of triton that costs more shows here first.
STEP_BUDGET = {('band_forward', 128): (21, 0.1),
               ('band_backward', 32): (73, 4.0),
               ('band_backward', 16): (150, 5.0)}


@pytest.mark.gpu_targets
def test_the_step_loop_stays_within_its_instruction_budget(rows):
    over = [r for r in rows if r['tensor_cores'] and (
        r['per_position'] > STEP_BUDGET[r['kernel'], r['block']][0] or
        r['tensor_core_per_position'] <
        STEP_BUDGET[r['kernel'], r['block']][1])]
    assert not over, triton_resources.format_table(over)


_SASS = """
        /*0000*/                   MOV R1, c[0x0][0x28] ;
        /*0010*/                   LDG.E R3, desc[UR4][R6.64] ;
        /*0020*/                   HMMA.1688.F32.TF32 R4, R8, R12, R4 ;
        /*0030*/                   IADD3 R2, R2, 0x1, RZ ;
        /*0040*/                   HGMMA.64x32x8.F32.TF32 R24, gdesc[UR4], R24 ;
        /*0050*/               @P0 BRA 0x10 ;
        /*0060*/              @!P1 BRA 0x0 ;
        /*0070*/                   EXIT ;
"""  # noqa: E501  (cuobjdump's columns, verbatim)
#: sm_100 and sm_120: a branch on a uniform predicate, scheduling notes
#: after the operands, and a wait for a barrier (a loop that loads nothing)
#: out of line
_SASS_BLACKWELL = """
        /*0000*/                   MOV R1, c[0x0][0x28]  &wr=0x0 ?trans1;
        /*0010*/                   LDG.E R3, desc[UR4][R6.64]  &wr=0x2 ?trans1;
        /*0020*/                   UTCHMMA tmem[UR8], gdesc[UR10], tmem[UR12] ;
        /*0030*/              @!P4 BRA 0x60  ?trans5;
        /*0040*/                   BRA.U UP0, 0x10  ?trans6;
        /*0050*/                   EXIT  ?trans5;
        /*0060*/                   SYNCS.PHASECHK.TRANS64.TRYWAIT P4, [UR4], R5 ;
        /*0070*/              @!P4 BRA 0x60 ;
        /*0080*/                   BRA 0x40 ;
"""  # noqa: E501  (cuobjdump's columns, verbatim)


def test_step_loop_and_cost_by_hand():
    """The step loop is the shortest a backward branch closes that loads
    from global memory."""
    opcodes = triton_resources.step_loop(_SASS)
    assert opcodes == ['LDG.E', 'HMMA.1688.F32.TF32', 'IADD3',
                       'HGMMA.64x32x8.F32.TF32', 'BRA']
    assert triton_resources.step_cost(opcodes) == (5, 2)
    opcodes = triton_resources.step_loop(_SASS_BLACKWELL)
    assert opcodes == ['LDG.E', 'UTCHMMA', 'BRA', 'BRA.U']
    assert triton_resources.step_cost(opcodes) == (4, 1)
    assert triton_resources.per_position(4, 4, 16) == 1.0
    # 1e8 positions at 50 instructions on 132 SMs of 4 schedulers, 1.5 GHz
    assert kernel_prediction.predicted_ms(1e8, 50, 132, 1.5) == \
        pytest.approx(1e8 * 50 / (132 * 4 * 1.5e9) * 1e3)
    with pytest.raises(ValueError, match='no loop'):
        triton_resources.step_loop(_SASS.replace('BRA', 'NOP'))
    with pytest.raises(ValueError, match='no loop'):
        triton_resources.step_loop(_SASS.replace('LDG', 'LDS'))


@pytest.mark.parametrize('registers, warps, shared, arch, programs', [
    (96, 4, 13312, 'sm_90', 5),    # 96 x 32 = 3072 a warp: 21 warps
    (128, 4, 5120, 'sm_90', 4),    # exactly 16 warps of 4096
    (129, 4, 5120, 'sm_90', 3),    # rounds up to 4352 a warp
    (32, 4, 0, 'sm_89', 12),       # 48 warps at most on sm_89
    (32, 1, 0, 'sm_90', 32),       # 32 programs at most
    (64, 4, 99 * 1024, 'sm_89', 1),  # shared: 100 KB on sm_89
    (32, 4, 0, 'sm_120', 12),      # 48 warps at most on sm_120 too
    (64, 4, 112 * 1024, 'sm_100', 2),  # 228 KB as on sm_90
])
def test_programs_per_sm_by_hand(registers, warps, shared, arch, programs):
    assert triton_resources.programs_per_sm(registers, warps, shared,
                                            arch) == programs


def _report(**environment):
    """A GPU report's JSON as dev/gpu_report.py writes it, its profile of
    one pass at bf16 (the band kernels and a product between them)."""
    run = dict(status='ok', precision='bf16', hidden=32,
               positions=106_000_000, rows=[
                   dict(kernel='band_backward', launches=1, ms=12.0),
                   dict(kernel='band_forward', launches=1, ms=4.0),
                   dict(kernel='sm90_xmma_gemm_f32f32', launches=2,
                        ms=0.3)])
    failed = dict(status='failed', precision='tf32', error='x')
    env = dict(gpu='NVIDIA H100 80GB HBM3', capability='sm_90', sms=132,
               sm_clock_mhz=1980.0)
    env.update(environment)
    return dict(environment=env,
                sections=dict(profile=dict(status='partial',
                                           rows=[failed, run])))


@pytest.mark.gpu_targets
def test_measured_beside_the_cost_models_floor(rows):
    """Each profiled band kernel's time against the issue floor of the
    variant a training pass launches (no input gradient, the default
    entries), compiled for the report's GPU; other kernels and failed
    profiles left out."""
    found = kernel_prediction.measured_against_predicted(_report(), rows)
    assert [(r['precision'], r['kernel']) for r in found] == [
        ('bf16', 'band_backward'), ('bf16', 'band_forward')]
    for row, entry, ms in zip(
            found, (triton_launch_choices.backward_configs(False, 'bf16')[0],
                    triton_launch_choices.FORWARD_CONFIGS[0]), (12.0, 4.0)):
        compiled, = [r for r in rows if r['arch'] == 'sm_90' and
                     r['kernel'] == row['kernel'] and r['hidden'] == 32 and
                     r['precision'] == 'bf16' and not r['input_grad'] and
                     r['block'] == entry.block]
        assert row['per_position'] == compiled['per_position']
        floor = 106_000_000 * compiled['per_position'] / (
            132 * 4 * 1.98e9) * 1e3
        assert row['predicted_ms'] == pytest.approx(floor)
        assert row['measured_ms'] == ms
        assert row['of_issue'] == pytest.approx(floor / ms)
    table = kernel_prediction.format_comparison(found, _report())
    assert table.startswith('NVIDIA H100 80GB HBM3 (sm_90, 132 SMs at 1980 '
                            'MHz')
    assert '| bf16 | band_backward |' in table


@pytest.mark.gpu_targets
@pytest.mark.parametrize('report, match', [
    (_report(sm_clock_mhz=None), 'no clock'),
    (_report(capability='sm_75'), 'names no GPU of'),
    (dict(_report(), sections=dict(profile=dict(status='not run'))),
     'no profile of a WGSE pass'),
    (dict(_report(), sections=dict(profile=dict(rows=[dict(
        status='ok', precision='bf16', rows=[dict(kernel='band_forward',
                                                  launches=1, ms=1.0)])]))),
     'not as dev/gpu_report.py writes it'),
    (dict(_report(), sections=dict(profile=dict(rows=[dict(
        status='ok', precision='fp64', hidden=32, positions=1,
        rows=[])]))), "at precision 'fp64', not one of"),
    ([1, 2], 'names no GPU of'),
])
def test_a_report_the_comparison_cannot_read(rows, report, match):
    with pytest.raises(ValueError, match=match):
        kernel_prediction.measured_against_predicted(report, rows)


def test_the_comparison_refuses_a_report_of_other_code(
        tmp_path, capsys, monkeypatch):
    """What is compiled here must be what ran there: a report whose code
    digest differs from this checkout's is refused before any compile."""
    monkeypatch.delenv('TRITON_INTERPRET')  # as the command line runs
    path = tmp_path / 'gpu.json'
    path.write_text(json.dumps(_report(code='0123456789abcdef')))
    with pytest.raises(SystemExit) as error:
        kernel_prediction.main(['--against', str(path)])
    assert error.value.code == 2
    assert 'measured other code (digest 0123456789abcdef)' in \
        capsys.readouterr().err


def test_the_comparison_refuses_a_file_that_is_no_report(
        tmp_path, capsys, monkeypatch):
    monkeypatch.delenv('TRITON_INTERPRET')
    path = tmp_path / 'gpu.json'
    path.write_text('[1, 2]')
    with pytest.raises(SystemExit):
        kernel_prediction.main(['--against', str(path)])
    assert f'{path} holds no report' in capsys.readouterr().err


@pytest.fixture
def hopper():
    """A skip where triton cannot compile for sm_90a here."""
    reason = triton_resources.cannot_compile()
    if reason:
        pytest.skip(reason)


@pytest.fixture(scope='session')
def predictions(built_once):
    """The predictor's times of a training pass's band kernels on an H200
    at 4x129x256x512, TF32 and bf16, compiled once a run."""
    def build(path):
        with open(path, 'w') as f:
            json.dump({p: kernel_prediction.predict_band_kernels(p)
                       for p in ('tf32', 'bf16')}, f)
    with open(built_once('band_kernel_predictions.json', build)) as f:
        return json.load(f)


#: The predictor's budget (milliseconds of each kernel's launch on an H200,
#: a WGSE training pass at 4x129x256x512; docs/wgse_speed.md, "A
#: predictor"): what the kernels as compiled by triton 3.6 are predicted to
#: take, rounded up. A change that the predictor says costs more shows here
#: first.
PREDICTED_BUDGET_MS = {('tf32', 'band_forward'): 4.5,
                       ('tf32', 'band_backward'): 24.5,
                       ('bf16', 'band_forward'): 3.3,
                       ('bf16', 'band_backward'): 15.5}


@pytest.mark.gpu_targets
def test_kernels_within_predicted_budget(hopper, predictions):
    assert {(p, k) for p in predictions for k in predictions[p]
            if k.startswith('band_') and not k.endswith(('cycles', 'sm'))
            } == set(PREDICTED_BUDGET_MS)
    over = {key: predictions[key[0]][key[1]] for key, budget in
            PREDICTED_BUDGET_MS.items()
            if not 0 < predictions[key[0]][key[1]] <= budget}
    assert not over, (over, PREDICTED_BUDGET_MS)
    for found in predictions.values():
        assert found['gpu'] == 'NVIDIA H200' and found['error'] == \
            kernel_prediction.PREDICTION_ERROR
        assert found['band_forward_programs_per_sm'] >= 2


def test_prediction_arguments_are_checked():
    for bad in (dict(precision='ieee'), dict(precision='tf64'),
                dict(hidden=64), dict(batch=0), dict(width=2.5),
                dict(clock_ghz=0), dict(sms=True)):
        with pytest.raises(ValueError, match='predict_band_kernels'):
            kernel_prediction.predict_band_kernels(**bad)


def test_makespan_by_hand():
    assert kernel_prediction.makespan([3, 3, 3], 2) == 6
    assert kernel_prediction.makespan([5, 1, 1, 1], 2) == 5
    assert kernel_prediction.makespan([2, 2], 8) == 2


_FORMER = '3123fe6'


def _at_former_commit(path):
    """``path`` as the repository held it at the former kernels' commit,
    or a skip where this checkout's history lacks it."""
    proc = subprocess.run(['git', 'show', f'{_FORMER}:{path}'],
                          cwd=os.path.dirname(os.path.dirname(
                              os.path.dirname(os.path.abspath(__file__)))),
                          capture_output=True, text=True)
    if proc.returncode:
        pytest.skip(f'this checkout\'s history lacks {_FORMER} ({path}): '
                    f'{proc.stderr.strip()}')
    return proc.stdout


@pytest.mark.gpu_targets
def test_the_predictor_explains_the_former_kernels_measurement(hopper,
                                                               tmp_path):
    """The one measurement of these kernels' kind on a GPU: the former
    pixel-major kernels' launches on an H200 (their autotuner's times of
    its chosen entries, per band, at 4x256x512 pixels, in the report of
    that commit). The predictor, from their compiled code alone, is within
    :data:`~wgse_bench.kernel_prediction.PREDICTION_ERROR` of each kernel's
    sum over the bands."""
    source = tmp_path / 'former_kernels.py'
    source.write_text(_at_former_commit(
        'wgse_mmseg/core/wgse/_triton_band_kernels.py'))
    report = json.loads(_at_former_commit('docs/gpu.json'))
    assert report['environment']['gpu'] == 'NVIDIA H200'
    measured = {}
    for key, choice in report['sections']['autotune']['chosen'].items():
        _, kernel, variant, pixels = (part.strip() for part in
                                      key.split('|'))
        if pixels == '<=524288 px' and 'H=32 tf32' in variant:
            length = int(variant.split()[0][2:])
            measured.setdefault(kernel, {})[length] = \
                choice['entry_ms'][choice['entry']]
    predicted = kernel_prediction.predict_former_kernels(str(source))
    for kernel in ('band_forward', 'band_backward'):
        want = sum(measured[kernel][n] for n in kernel_prediction.PAPER_BANDS)
        got = sum(predicted[kernel][str(n)]
                  for n in kernel_prediction.PAPER_BANDS)
        assert abs(got / want - 1) <= kernel_prediction.PREDICTION_ERROR, (
            kernel, got, want)


@pytest.mark.gpu_targets
def test_ptxas_serialises_no_wgmma_product(hopper):
    """ptxas' report of each training variant for sm_90a names no
    serialised ``wgmma`` products (its notice C7514: each waited for before
    the next, because other instructions read their accumulators)."""
    reports = {p: triton_resources.ptxas_reports(p)
               for p in ('tf32', 'bf16')}
    assert all(set(r) == {'band_forward', 'band_backward'} and
               all("for 'sm_90a'" in text for text in r.values())
               for r in reports.values())
    serialised = {(p, k): text for p, r in reports.items()
                  for k, text in r.items() if 'C7514' in text}
    assert not serialised, serialised
