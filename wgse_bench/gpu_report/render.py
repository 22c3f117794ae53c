"""A report as docs/gpu.md (every section a table, a section not measured
saying why) and gpu.json beside it (every number and sample), and the JSON
read back for a resumed run."""
import json
import os
from typing import Any, Dict, List, Optional, Sequence, Union

from wgse_mmseg.fileio.atomic import atomic_output
from wgse_mmseg.fileio.bounded_reads import load_json_file
from wgse_mmseg.limits import LOG_FILE_LIMIT_BYTES

from .. import wgse_choices, wgse_profile
from ..markdown import markdown_table
from .measure import REDUCED_PRECISION_NOTE
from .sections import SECTIONS, shape_text

__all__ = []


def _num(value: Optional[float], digits: Union[int, str] = 2) -> str:
    """``value`` with ``digits`` decimals (or that format), ``'-'`` for
    ``None``."""
    spec = f'.{digits}f' if isinstance(digits, int) else digits
    return '-' if value is None else format(value, spec)


def _timing(summary: Optional[Dict], digits: int = 1) -> str:
    return '-' if summary is None else \
        f"{summary['median']:.{digits}f} ± {summary['mad']:.{digits}f}"


def _error_line(row: Dict) -> str:
    """The last line of a row's recorded error, for a table cell."""
    return row['error'].splitlines()[-1][:120]


def _failed(section: Dict) -> str:
    return (f"**Failed**: `{section['error'].splitlines()[-1]}` "
            '(the whole message is in the JSON).\n')


def _row_status(row: Dict) -> str:
    return 'ok' if row['status'] == 'ok' else 'failed: ' + _error_line(row)


def _range(row: Dict) -> str:
    return f"{row['min_ms']:.2f}-{row['max_ms']:.2f}" if 'min_ms' in row \
        else '-'


def _ceilings_lines(section: Dict[str, Any]) -> List[str]:
    copy, matmul = section['copy'], section['matmul_bf16']
    out = ['What the device reached in this run, the ceilings the other '
           'figures are read against: a device-to-device copy (bytes read '
           'plus written), a bf16 matrix product of random matrices through '
           'torch (median of the repeats), and the clocks `nvidia-smi` read '
           'before the copy and after the product.', '',
           markdown_table(['ceiling', 'size', 'median ms', 'rate'], [
               ['copy', f"{copy['bytes'] / 2**20:.0f} MiB",
                _num(copy['ms'], 3), f"{copy['tb_per_s']:.2f} TB/s"],
               ['bf16 matrix product', f"{matmul['size']}^3",
                _num(matmul['ms'], 3), f"{matmul['tflops']:.0f} TFLOP/s"]]),
           '']
    for when in ('idle', 'loaded'):
        clocks = section[f'clocks_{when}']
        out += [f'Clocks, {when}: ' + (clocks['note'] if 'note' in clocks
                                       else ', '.join(
                                           f'{k} {v}' for k, v in
                                           clocks.items())) + '.', '']
    return out


def _band_kernels_lines(section: Dict[str, Any]) -> List[str]:
    notes = {r.get('prediction_note') for r in section['rows']} - {None}
    return [f"Each band kernel's launch over the coefficients of a "
            f"{shape_text(section['shape'])} batch (WGSE's default "
            'networks), as a training pass launches it (the backward from '
            "the forward's mask, no input gradient); median and range of "
            'the timed launches, beside the resources tool\'s prediction.',
            '', markdown_table(
                ['kernel', 'precision', 'launch', 'median ms', 'min-max ms',
                 'predicted ms', 'measured / predicted', 'status'],
                [[r['kernel'], r['precision'], r.get('launch', '-'),
                  _num(r.get('median_ms')), _range(r),
                  _num(r.get('predicted_ms')),
                  _num(r.get('measured_vs_predicted')), _row_status(r)]
                 for r in section['rows']]), ''] + \
        [f'Prediction: {note}.' for note in sorted(notes)] + \
        ([''] if notes else [])


def _wgse_lines(section: Dict[str, Any]) -> List[str]:
    return [f"db8, 5 levels, 32 channels, {shape_text(section['shape'])}, "
            'forward+backward, the output gradient given (a fixed random '
            'tensor, as a segmentor hands WGSE one); TF32 for both passes or '
            'bf16 autocast for the forward; the reference design in a fresh '
            'process at torch\'s default (TF32), the backends in this one; '
            'peak: growth of CUDA memory allocated in one pass.', '',
            markdown_table(
                ['implementation', 'precision', 'median ms', 'min-max ms',
                 'peak MiB', 'time / reference', 'predicted ms', 'status'],
                [[wgse_choices.IMPLEMENTATIONS[r['impl']], r['precision'],
                  _num(r.get('median_ms')), _range(r) if 'min_ms' in r else
                  (f"{1e3 * r['min_s']:.2f}-{1e3 * r['max_s']:.2f}"
                   if 'min_s' in r else '-'),
                  _num(r.get('peak_mib'), 0),
                  _num(r.get('time_vs_reference'), 3),
                  _num(r.get('predicted_ms')), _row_status(r)]
                 for r in section['rows']]), '']


def _first_use_lines(section: Dict[str, Any]) -> List[str]:
    out = ["What `backend='auto'` checks before it first runs the Triton "
           'kernel on the device for a training step: the launch entries it '
           'runs, forward and backward, against the `torch` backend in '
           'float64 (`wgse_mmseg/core/wgse/first_use_check.py`); where it '
           "fails, 'auto' runs `torch`.", '']
    if section.get('rows'):
        out += [markdown_table(
            ['precision', 'passed', 'max rel. error', 'tolerance', 'failure',
             'seconds', "'auto' runs"],
            [[r['precision'],
              {True: 'yes', False: 'NO'}.get(r['passed'], r.get('note')),
              _num(r.get('max_error'), '.1e'),
              _num(r.get('tolerance'), '.0e'),
              r.get('failure') or '-',
              _num(r.get('seconds')), r.get('auto_runs', '-')]
             for r in section['rows']]), '']
    elif section.get('note'):
        out += [section['note'], '']
    return out


def _stalls_lines(section: Dict[str, Any]) -> List[str]:
    out = [f"One launch of each band kernel at {shape_text(section['shape'])}"
           f", profiled with {section['tool']}: its time and, from Nsight "
           'Compute, why its warps stalled (warps stalled for each reason '
           'per issued instruction, the largest first) and how often the '
           'schedulers issued.', '']
    if section.get('note'):
        out += [section['note'] + '.', '']
    rows = []
    for r in section['rows']:
        stalls = sorted((r.get('stalls') or {}).items(),
                        key=lambda item: -item[1])
        rows.append([r['kernel'], r['precision'], _num(r.get('ms'), 3),
                     _num(r.get('issue_active_pct'), 1),
                     _num(r.get('sm_throughput_pct'), 1),
                     ', '.join(f'{k} {v:.2f}' for k, v in stalls[:5]) or
                     '-'])
    return out + [markdown_table(
        ['kernel', 'precision', 'ms', 'issue active %', 'SM throughput %',
         'stall reasons (largest five)'], rows), '']


def _tensor_cores_lines(section: Dict[str, Any]) -> List[str]:
    out = ['A loop of `tl.dot` products at each band kernel\'s tile '
           '(block x hidden times hidden x hidden, its warps), one float32 '
           'accumulator a program, the operands loaded once: the tensor '
           'cores\' rate at those shapes, the instruction the PTX holds, and '
           'that rate over the large bf16 product\'s.', '']
    if section.get('note'):
        out += [section['note'], '']
    return out + [markdown_table(
        ['kernel tile', 'precision', 'instruction', 'median ms', 'TFLOP/s',
         'of the bf16 product', 'max rel. error', 'status'],
        [[f"{r['kernel']} {r['block']}x{r['hidden']}, {r['num_warps']} "
          'warps', r['precision'], r.get('instruction', '-'),
          _num(r.get('median_ms'), 3), _num(r.get('tflops'), 1),
          _num(r.get('of_matmul'), 3), _num(r.get('max_rel_error'), '.1e'),
          _row_status(r)] for r in section['rows']]), '']


def _profile_lines(section: Dict[str, Any]) -> List[str]:
    out = ['Device kernels of one forward+backward at the shape above '
           '(torch.profiler, after a warm-up pass): time, share of the span '
           'from the first kernel to the last, the gaps no kernel covers, '
           "and the band kernels' H x H products in TFLOP/s against the "
           "device's dense peak (wgse_bench/wgse_profile.py).", '']
    if section.get('note'):
        out += [section['note'], '']
    for row in section.get('rows', []):
        if row['status'] == 'ok':
            out += [f"{row['precision']} ({row['backend']}): span "
                    f"{row['span_ms']:.2f} ms", '',
                    *wgse_profile.table_lines(row), '']
        else:
            out += [f"{row['precision']}: {_row_status(row)}", '']
    return out


def _within(row: Dict) -> str:
    """The correctness table's last column for ``row``."""
    if row.get('error'):
        return 'NO: ' + _error_line(row)
    if row['ok'] is None:
        return 'measured' if row.get('note') == REDUCED_PRECISION_NOTE \
            else row['note']
    return 'yes' if row['ok'] else 'NO'


def _correctness_lines(section: Dict[str, Any]) -> List[str]:
    out = [f"WGSE at {shape_text(section['shape'])}, the same weights "
           'in float64 (backend `torch`) as reference; error: largest over '
           'the output and every parameter gradient of |got - float64| / '
           'the largest magnitude of that tensor (a hundredth of the '
           'largest of all at least). Full float32 is held to its '
           'tolerance; TF32 and bf16 are ' + REDUCED_PRECISION_NOTE + '.',
           '']
    if 'rows' in section:
        out += [markdown_table(
            ['backend', 'precision', 'max rel. error', 'in', 'tolerance',
             'within'],
            [[r['backend'], r['precision'],
              _num(r['max_rel_error'], '.1e'), r['tensor'] or '-',
              _num(r['tolerance'], '.0e'), _within(r)]
             for r in section['rows']]), '']
    return out


def model_table(rows: Sequence[Dict], latency: bool) -> str:
    """The segmentation rows as a Markdown table (with the batch-1 latency
    columns where ``latency``)."""
    headers = ['model', 'input', 'enh. backend', 'step ms', 'step / raw',
               'peak MiB', 'memory / raw']
    if latency:
        headers += ['latency ms (b1)', 'added ms']
    headers.append('status')
    table = []
    for r in rows:
        ok = r['status'] == 'ok'
        line = [r['model'], r['enhancer'],
                (r.get('enhancer_backend') or '-') if ok else '-',
                _timing(r.get('step_ms')), _num(r.get('step_vs_raw')),
                _num(r['memory']['peak_mb'], 0) if ok else '-',
                _num(r.get('memory_vs_raw'))]
        if latency:
            line += [_timing(r.get('latency_ms'), 2),
                     _num(r.get('added_latency_ms'))]
        table.append(line + [_row_status(r)])
    return markdown_table(headers, table)


def _segmentation_lines(section: Dict[str, Any]) -> List[str]:
    return [f"Batch {section['shape'][0]}, T={section['shape'][1]}, "
            f"{section['shape'][2]}x{section['shape'][3]}, "
            "`model.train_step` with the config's optimiser; time: median "
            '± MAD; peak: CUDA memory allocated (CPU: peak RSS) during the '
            'timed steps; ratios: WGSE over raw spikes.', '',
            model_table(section['rows'], latency=False), '']


def _latency_lines(section: Dict[str, Any]) -> List[str]:
    return ['`model.test_step` on one stream (preprocessing, enhancer, '
            'segmentor, resize, argmax), no gradients; WGSE\'s added '
            'milliseconds over raw spikes.', '',
            markdown_table(
                ['model', 'input', 'latency ms', 'added ms', 'status'],
                [[r['model'], r['enhancer'], _timing(r['latency_ms'], 2),
                  _num(r['added_latency_ms']),
                  'ok' if r['status'] == 'ok' else 'failed']
                 for r in section['rows']]), '']


def _paper_lines(section: Dict[str, Any]) -> List[str]:
    return [f"{shape_text(section['shape'])} (batch x T x H x W), training "
            'step as above.', '', model_table(section['rows'], False), '']


def _targets_lines(section: Dict[str, Any]) -> List[str]:
    return [markdown_table(
        ['target', 'this run', 'at most', 'aim', 'met'],
        [[t['what'], '-' if t['value'] is None else
          f"{t['value']:.2f} {t['unit']}",
          f"{t['target']} {t['unit']}",
          '-' if t['moonshot'] is None else f"{t['moonshot']} {t['unit']}",
          'not measured' if t['met'] is None else
          ('yes' if t['met'] else 'no') +
          (' (aim too)' if t['moonshot_met'] else '')]
         for t in section['rows']]), '']


#: The keys of a section that measured nothing (no rows; a note says why)
_EMPTY = {'status', 'seconds', 'rows', 'note'}
#: Each section's heading in docs/gpu.md and what goes under it.
_SECTION_TEXT = dict(
    ceilings=("The device's ceilings", _ceilings_lines),
    band_kernels=('The band kernels', _band_kernels_lines),
    wgse=('WGSE forward+backward', _wgse_lines),
    first_use=('First-use check', _first_use_lines),
    stalls=('One launch of each band kernel, profiled', _stalls_lines),
    tensor_cores=("Tensor-core products at the kernels' tiles",
                  _tensor_cores_lines),
    profile=('One WGSE pass, kernel by kernel', _profile_lines),
    correctness=('Correctness against float64', _correctness_lines),
    segmentation=('Training steps', _segmentation_lines),
    latency=('Latency at batch 1', _latency_lines),
    paper=("The paper's shape", _paper_lines),
    targets=('Against the targets (an H100 or H200)', _targets_lines))


def format_report(report: Dict[str, Any], command: str) -> str:
    """docs/gpu.md: every section as a table (a section not measured says
    so), the environment and the command that produced it."""
    env, sections = report['environment'], report['sections']
    device = env.get('gpu', f"{env['device']} ({env['cpu']})")
    out = [f'# WGSE on {device}', '',
           'Written by `' + command + '` (docs/wgse_speed.md, "On a GPU"); '
           'every ratio is against a baseline measured in the same run. '
           'The JSON beside this file has every number and raw sample.', '',
           markdown_table(['', ''], [[k, v] for k, v in env.items()]), '']
    if not env['device'].startswith('cuda'):
        out += ['**Not a GPU run**: a dry run on the CPU at tiny shapes '
                '(Triton in its interpreter); its figures say nothing about '
                'a GPU.', '']
    if report.get('kept'):
        out += ['Kept from an earlier run of the same plan and code on the '
                'same machine and software (`--resume`): ' +
                ', '.join(report['kept']) + '.', '']
    for name in SECTIONS:
        section = sections[name]
        heading, lines = _SECTION_TEXT[name]
        out += [f'## {heading}', '']
        if section['status'] == 'not run':
            out += [f"**Not run**: {section['note']}.", '']
            continue
        if section['status'] == 'failed' and 'rows' not in section and \
                name not in ('correctness', 'first_use'):
            out.append(_failed(section))
            continue
        if set(section) <= _EMPTY and not section.get('rows'):
            out += [section.get('note') or 'Nothing measured.', '']
            continue
        out += lines(section)
        if name in ('correctness', 'first_use') and \
                section['status'] != 'ok':
            out.append(_failed(section))
    out += [f"The report took {report['seconds']:.0f} s.", '']
    return '\n'.join(out)


def read_report(path: str) -> Dict[str, Any]:
    """The report whose JSON :func:`write_report` wrote at ``path``.

    Raises:
        ValueError: naming ``path``, where it cannot be read as JSON or
            holds no JSON object.
    """
    try:
        report = load_json_file(path, 'GPU report', LOG_FILE_LIMIT_BYTES)
    except (OSError, ValueError) as err:
        raise ValueError(f'{path} cannot be read as a report ({err})')
    if not isinstance(report, dict):
        raise ValueError(f'{path} holds no report (a JSON object), but '
                         f'{type(report).__name__}')
    return report


def write_report(report: Dict[str, Any], out_dir: str, command: str) -> None:
    """``out_dir/gpu.json`` and ``out_dir/gpu.md`` of ``report`` (what
    :func:`~wgse_bench.gpu_report.run_report` returns), each whole or not at
    all; ``command`` is
    the command line the page says wrote it."""
    with atomic_output(os.path.join(out_dir, 'gpu.json')) as f:
        f.write(json.dumps(report, indent=1).encode())
    with atomic_output(os.path.join(out_dir, 'gpu.md')) as f:
        f.write(format_report(report, command).encode())
