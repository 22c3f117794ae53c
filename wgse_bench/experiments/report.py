"""Reports of an experiment grid: ``results.csv``, ``results.md``,
``accuracy_vs_time.png`` and ``loss_curves.png``.

:func:`report` aggregates every finished run (:func:`.aggregate.aggregate`)
and writes the four files, each atomically; ``results.md`` starts with the
command that made it, the grid's settings and the machine.
"""
import csv
import io
import os.path as osp
from typing import Any, Dict, List

from mmengine.config import Config

from wgse_mmseg.fileio.atomic import atomic_output
from wgse_mmseg.fileio.bounded_reads import load_json_file

from ..markdown import markdown_table
from .aggregate import aggregate
from .grid import Entry
from .settings import ExperimentSettings

CSV_COLUMNS = ['name', 'model', 'enhancer', 'seeds', 'mIoU_mean',
               'mIoU_std', 'mAcc_mean', 'mAcc_std', 'aAcc_mean', 'aAcc_std',
               'params', 'enhancer_params', 'ms_per_image_mean',
               'ms_per_image_std', 'train_seconds_mean', 'train_seconds_std',
               'final_loss_mean', 'final_loss_std', 'loss_change_mean',
               'loss_change_std', 'gflops', 'enhancer_gflops',
               'train_step_ms', 'train_memory_mb', 'torch_windows_per_s',
               'onnxruntime_windows_per_s']


def read_deployment(path: str) -> Dict[str, Dict[str, Any]]:
    """Entry name -> its result in a JSON file of
    ``tools/analysis_tools/benchmark_deployment.py``
    (:func:`~wgse_bench.deployment.measure_deployment`); a
    ``ValueError`` names the file if it is not one."""
    try:
        results = load_json_file(path, 'deployment benchmark')['results']
        return {r['name']: dict(
            torch=float(r['torch_eager']['windows_per_s']),
            onnxruntime=float(r['onnxruntime']['windows_per_s']),
            shape=[int(v) for v in r['shape']],
            batch_size=int(r['batch_size']),
            environment=dict(r['environment'])) for r in results}
    except (ValueError, KeyError, TypeError) as err:
        raise ValueError(f'{path}: not a JSON file of '
                         f'benchmark_deployment.py ({type(err).__name__}: '
                         f'{err})') from None


def _deployment_columns(row: Dict[str, Any]) -> Dict[str, Any]:
    """Windows per second in torch eager and ONNX Runtime of the entry
    (:func:`read_deployment`); ``None`` each where not measured."""
    measured = row.get('deployment')
    return dict(torch_windows_per_s=measured and measured['torch'],
                onnxruntime_windows_per_s=measured and
                measured['onnxruntime'])


def _benchmark_columns(row: Dict[str, Any]) -> Dict[str, Any]:
    """GFLOPs (batch 1), training-step ms and peak training memory (MB)
    of the entry's benchmark; ``None`` each where not measured."""
    measured = row.get('benchmark')
    if measured is None:
        return dict(gflops=None, enhancer_gflops=None, train_step_ms=None,
                    train_memory_mb=None)

    def giga(flops):
        return None if flops is None else flops / 1e9

    return dict(gflops=giga(measured['flops']),
                enhancer_gflops=giga(measured['enhancer_flops']),
                train_step_ms=measured['train_step_ms']['median'],
                train_memory_mb=measured['memory']['peak_mb'])


def write_csv(rows: List[Dict[str, Any]], path: str) -> None:
    """``rows`` (of :func:`.aggregate.aggregate`) as :data:`CSV_COLUMNS`,
    floats rounded to four decimals, the benchmark's columns empty where
    not measured."""
    text = io.StringIO()
    writer = csv.DictWriter(text, CSV_COLUMNS, extrasaction='ignore',
                            lineterminator='\n')
    writer.writeheader()
    for row in rows:
        row = dict(row, **_benchmark_columns(row),
                   **_deployment_columns(row))
        writer.writerow({k: round(v, 4) if isinstance(v, float) else v
                         for k, v in row.items()})
    with atomic_output(path) as f:
        f.write(text.getvalue().encode())


def _pm(row: Dict[str, Any], key: str, scale: float = 1,
        digits: int = 2) -> str:
    if row[f'{key}_mean'] is None:
        return '-'
    mean, std = row[f'{key}_mean'] * scale, row[f'{key}_std']
    spread = '' if std is None else f' ± {std * scale:.{digits}f}'
    return f'{mean:.{digits}f}{spread}'


LOSS_PLOT = 'loss_curves.png'


def _total_training(rows: List[Dict[str, Any]]) -> str:
    """The training processes' wall time of all runs, summed, in the unit
    that shows it (seconds, minutes or hours)."""
    seconds = sum(r['train_seconds_mean'] * r['seeds'] for r in rows)
    if seconds < 120:
        return f'{seconds:.0f} s'
    if seconds < 2 * 3600:
        return f'{seconds / 60:.1f} min'
    return f'{seconds / 3600:.1f} hours'


def _loads(rows: List[Dict[str, Any]]) -> str:
    """The range of the 1-minute load averages the runs recorded."""
    loads = [r.get('environment', {}).get('load_average') for r in rows]
    loads = [load for load in loads if load is not None]
    if not loads:
        return 'not recorded'
    low, high = min(loads), max(loads)
    return f'{low:.1f}' if high - low < 0.05 else f'{low:.1f}-{high:.1f}'


def write_markdown(rows: List[Dict[str, Any]], path: str, command: str,
                   settings: ExperimentSettings, grid: Config,
                   plot_name: str) -> None:
    """The results table (``rows`` of :func:`.aggregate.aggregate`), with
    the command, settings and machine."""
    def number(value, digits):
        return '-' if value is None else f'{value:.{digits}f}'

    table_rows = []
    for r in rows:
        cost = _benchmark_columns(r)
        table_rows.append([
            r['name'], r['enhancer'], r['seeds'], _pm(r, 'mIoU'),
            _pm(r, 'mAcc'), _pm(r, 'aAcc'), f"{r['params'] / 1e6:.3f}",
            _pm(r, 'ms_per_image', digits=1),
            _pm(r, 'train_seconds', 1 / 60, 1), _pm(r, 'final_loss'),
            _pm(r, 'loss_change', 100, 1), number(cost['gflops'], 2),
            number(cost['train_step_ms'], 0),
            number(cost['train_memory_mb'], 0)])
    headers = ['entry', 'enhancer', 'seeds', 'mIoU', 'mAcc', 'aAcc',
               'params (M)', 'ms / image', 'train time (min)', 'final loss',
               'loss change, last quarter (%)', 'GFLOPs', 'train step (ms)',
               'train memory (MB)']
    deployed = [r['deployment'] for r in rows if r.get('deployment')]
    if deployed:  # the deployment columns, where measured
        headers += ['windows/s torch', 'windows/s ONNX Runtime']
        for cells, r in zip(table_rows, rows):
            speed = _deployment_columns(r)
            cells += [number(speed['torch_windows_per_s'], 2),
                      number(speed['onnxruntime_windows_per_s'], 2)]
    table = markdown_table(headers, table_rows)
    env = rows[0]['environment']
    options = ', '.join(f'{k}={v}' for k, v in grid.cfg_options.items())
    grid_name = osp.relpath(osp.abspath(settings.grid))
    seeds = ' '.join(map(str, settings.seeds))
    lines = [
        '# Accuracy against time per image', '',
        f'Grid `{grid_name}` ({options}, {settings.schedule}, seeds {seeds}) '
        f'on `{settings.data_root}`, made with:', '', '```bash', command,
        '```', '',
        f"Machine: {env['cpu']} ({env['cpu_count']} logical cores, "
        f"{env['torch_threads']} torch threads); torch {env['torch']}, "
        f"mmcv {env['mmcv']}, mmengine {env['mmengine']}, "
        f"mmsegmentation {env['mmsegmentation']}, python {env['python']}; "
        f"{env['platform']}.", '', table, '',
        '- mIoU, mAcc, aAcc: % on the validation set (MMSeg `IoUMetric`) of '
        'the final checkpoint; mean ± standard deviation over seeds (no '
        'spread with one seed).',
        '- params: used at inference, enhancer included, auxiliary head '
        'excluded.',
        '- ms / image: median of batch-1 inference (preprocessing, enhancer, '
        'segmentor, resize) on a validation-sized stream '
        f"({'x'.join(map(str, rows[0]['image_size']))}), per run; mean ± "
        'standard deviation over seeds.',
        '- train time: wall time of the training process, start-up '
        'included; mean ± standard deviation over seeds. All runs of the '
        f'table trained for {_total_training(rows)} in all (their '
        'training processes\' wall time, summed), at a 1-minute load '
        f'average of {_loads(rows)} (the machine\'s, as each run ended).',
        '- final loss: the mean logged training loss over the last quarter '
        'of the iterations; loss change: that mean against the quarter '
        'before (-5.0: still 5 % lower), the measure of how flat the curve '
        'had become; mean ± standard deviation over seeds.',
        '- GFLOPs (one stream, batch 1), train step (ms) and train memory '
        '(peak, MB): the package\'s benchmark '
        '(`wgse_bench.segmentation.benchmark_config`, as '
        '`tools/analysis_tools/benchmark.py`) of each entry at the training '
        'crop and batch size, measured once per entry (`--benchmark`; '
        'run it with nothing else loading the machine); `-`: not '
        'measured.',
        *_deployment_note(deployed), '',
        f'![mIoU against ms per image]({plot_name})', '',
        f'![Training loss curves]({LOSS_PLOT})'
    ]
    with atomic_output(path) as f:
        f.write(('\n'.join(lines) + '\n').encode())


def _deployment_note(deployed: List[Dict[str, Any]]) -> List[str]:
    """The bullet that says how the deployment columns were measured."""
    if not deployed:
        return []
    first, env = deployed[0], deployed[0]['environment']
    loads = [d['environment'].get('load_average') for d in deployed]
    loads = [f'{v:.1f}' for v in loads if v is not None]
    return [
        '- windows/s torch, windows/s ONNX Runtime: windows '
        f"({'x'.join(map(str, first['shape']))}, T x H x W) per second, "
        f"batch {first['batch_size']}, of `model.test_step` in torch "
        '(eager, the enhancer on its default backend) and of the model '
        'exported to ONNX (`tools/deployment/pytorch2onnx.py`) in ONNX '
        'Runtime, argmax included, random weights; measured by '
        '`tools/analysis_tools/benchmark_deployment.py` on '
        f"{env['cpu']} ({env['cpu_count']} logical cores, "
        f"{env['torch_threads']} torch threads), torch {env['torch']}, "
        f"onnxruntime {env.get('onnxruntime', '?')}; 1-minute load "
        f"average {', '.join(loads) or 'unknown'}; `-`: not measured."]


def plot(rows: List[Dict[str, Any]], path: str) -> None:
    """mIoU against ms per image (log scale), error bars one standard
    deviation over seeds; marker: model, colour: enhancer type, label:
    enhancer name. Where rows have deployment measurements
    (:func:`read_deployment`), a second panel: mIoU against windows per
    second, torch eager hollow and ONNX Runtime filled, joined per entry."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    models = sorted({r['model'] for r in rows})
    markers = dict(zip(models, 'osD^v<>p*h'))
    types = sorted({r['enhancer'].split('(')[0] for r in rows})
    colours = {t: plt.get_cmap('tab10')(i % 10) for i, t in enumerate(types)}
    deployed = [r for r in rows if r.get('deployment')]
    figure, panels = plt.subplots(1, 2 if deployed else 1, squeeze=False,
                                  figsize=(16 if deployed else 9, 6))
    axes = panels[0][0]
    for row in rows:
        axes.errorbar(row['ms_per_image_mean'], row['mIoU_mean'],
                      xerr=row['ms_per_image_std'], yerr=row['mIoU_std'],
                      marker=markers[row['model']], linestyle='none',
                      color=colours[row['enhancer'].split('(')[0]],
                      capsize=2)
        axes.annotate(row['name'][len(row['model']) + 1:],
                      (row['ms_per_image_mean'], row['mIoU_mean']),
                      fontsize=6, xytext=(3, 3), textcoords='offset points')
    handles = [Line2D([], [], marker=markers[m], color='grey',
                      linestyle='none', label=m) for m in models]
    handles += [Line2D([], [], marker='o', color=colours[t],
                       linestyle='none', label=f'enhancer: {t}')
                for t in types]
    axes.legend(handles=handles, fontsize=7, loc='best')
    axes.set_xscale('log')
    axes.set_xlabel('ms per image (batch 1, log scale)')
    axes.set_ylabel('mIoU (%)')
    axes.set_title('Accuracy against time per image')
    axes.grid(True, which='both', alpha=0.3)
    if deployed:
        speed = panels[0][1]
        for row in deployed:
            colour = colours[row['enhancer'].split('(')[0]]
            marker = markers[row['model']]
            eager = row['deployment']['torch']
            onnx = row['deployment']['onnxruntime']
            speed.plot([eager, onnx], [row['mIoU_mean']] * 2, color=colour,
                       linewidth=0.8)
            speed.plot(eager, row['mIoU_mean'], marker=marker,
                       markerfacecolor='none', color=colour,
                       linestyle='none')
            speed.plot(onnx, row['mIoU_mean'], marker=marker, color=colour,
                       linestyle='none')
            speed.annotate(row['name'][len(row['model']) + 1:],
                           (onnx, row['mIoU_mean']), fontsize=6,
                           xytext=(3, 3), textcoords='offset points')
        speed.legend(handles=[
            Line2D([], [], marker='o', markerfacecolor='none', color='grey',
                   linestyle='none', label='torch eager'),
            Line2D([], [], marker='o', color='grey', linestyle='none',
                   label='ONNX Runtime')], fontsize=7, loc='best')
        speed.set_xscale('log')
        speed.set_xlabel('windows per second (CPU, log scale)')
        speed.set_ylabel('mIoU (%)')
        speed.set_title('Accuracy against deployed speed')
        speed.grid(True, which='both', alpha=0.3)
    figure.tight_layout()
    with atomic_output(path) as f:
        figure.savefig(f, format='png', dpi=150)
    plt.close(figure)


def plot_loss_curves(rows: List[Dict[str, Any]], path: str) -> None:
    """The training loss against iterations, one panel per model, one line
    per entry (the mean over its seeds at the iterations all of them
    logged; ten colours, then the next line style), the seeds' range
    shaded."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    models = list(dict.fromkeys(r['model'] for r in rows))
    figure, axes = plt.subplots(1, len(models), squeeze=False,
                                figsize=(6.5 * len(models), 5))
    for axis, model in zip(axes[0], models):
        model_rows = [r for r in rows if r['model'] == model]
        colours = plt.get_cmap('tab10')
        drawn = 0
        for index, row in enumerate(model_rows):
            curves = [dict(c) for c in row['loss_curves'] if c]
            if not curves:
                continue
            steps = sorted(set.intersection(*(set(c) for c in curves)))
            if not steps:
                continue
            losses = np.array([[c[s] for s in steps] for c in curves])
            colour = colours(index % 10)
            drawn += 1
            axis.plot(steps, losses.mean(0), color=colour, linewidth=1.2,
                      linestyle=('-', '--', ':')[index // 10 % 3],
                      marker='o' if len(steps) < 5 else None, markersize=3,
                      label=row['name'][len(model) + 1:])
            axis.fill_between(steps, losses.min(0), losses.max(0),
                              color=colour, alpha=0.15, linewidth=0)
        axis.set_title(f'{model}: training loss (mean over seeds)')
        axis.set_xlabel('iteration')
        axis.set_ylabel('loss')
        axis.grid(True, alpha=0.3)
        if drawn:
            axis.legend(fontsize=7, ncol=2)
        else:  # no run logged a loss: say why instead of an empty panel
            axis.text(0.5, 0.5, 'no training loss logged: the runs were\n'
                      'shorter than default_hooks.logger.interval',
                      ha='center', va='center', transform=axis.transAxes)
    figure.tight_layout()
    with atomic_output(path) as f:
        figure.savefig(f, format='png', dpi=120)
    plt.close(figure)


def report(entries: List[Entry], settings: ExperimentSettings,
           grid: Config, command: str) -> List[Dict[str, Any]]:
    """Aggregate the finished runs of ``entries`` over ``settings.seeds``
    and write the CSV, Markdown and plots to ``settings.report_to``;
    ``command`` heads the Markdown (how to make it again)."""
    rows = aggregate(entries, settings.seeds, settings.work_dir)
    if not rows:
        print('no finished runs to report')
        return rows
    if settings.deployment is not None:
        deployment = read_deployment(settings.deployment)
        for row in rows:
            row['deployment'] = deployment.get(row['name'])
    report_dir = settings.report_to
    plot_path = osp.join(report_dir, 'accuracy_vs_time.png')
    plot(rows, plot_path)
    plot_loss_curves(rows, osp.join(report_dir, LOSS_PLOT))
    write_csv(rows, osp.join(report_dir, 'results.csv'))
    write_markdown(rows, osp.join(report_dir, 'results.md'), command,
                   settings, grid, osp.basename(plot_path))
    print(f'{len(rows)} entries reported in {report_dir}: results.md, '
          f'results.csv, accuracy_vs_time.png, {LOSS_PLOT}')
    return rows
