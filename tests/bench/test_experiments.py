"""tools/analysis_tools/run_experiments.py: the grids, the options it passes to
the train and test tools, aggregation and reports, and one tiny run end to
end."""
import argparse
import ast
import csv
import dataclasses
import glob
import importlib.util
import json
import math
import os
import os.path as osp
import subprocess
import sys

import pytest

from mmseg.registry import MODELS
from wgse_mmseg import register_all_modules
from wgse_bench import experiments as runner
from wgse_bench.experiments import ExperimentSettings, StaleRunError
from wgse_mmseg.argument_checks import ArgumentError
from wgse_mmseg.utils.config import add_runner_arguments, load_config
from wgse_mmseg.data_generation.synthetic import make_synthetic_dataset

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
RUNNER = osp.join(ROOT, 'tools', 'analysis_tools', 'run_experiments.py')
GRID_CPU = osp.join(ROOT, 'configs', 'experiments', 'grid_cpu.py')
GRID_FULL = osp.join(ROOT, 'configs', 'experiments', 'grid_full.py')
GRID_CONVERGED = osp.join(ROOT, 'configs', 'experiments',
                          'grid_converged_cpu.py')

_spec = importlib.util.spec_from_file_location('run_experiments', RUNNER)
cli = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cli)


def wgse_sweep(entries):
    return {(e.enhancer['wavelet'], e.enhancer['level']) for e in entries
            if e.enhancer and e.enhancer['type'] == 'WGSE' and
            e.enhancer.get('dim') == 1}


def test_cpu_grid_covers_every_representation_on_both_models():
    register_all_modules()  # the enhancers' registry names
    grid, entries = runner.load_grid(GRID_CPU)
    names = {e.name for e in entries}
    for model in ('segformer_b0', 'pspnet'):
        for enhancer in ('raw', 'tfp', 'tfi', 'mean_spatial',
                         'mean_temporal', 'wgse1d', 'wgse2d', 'wgse3d'):
            assert f'{model}_{enhancer}' in names
    sweep = wgse_sweep(entries)
    assert {w for w, _ in sweep} == {'db1', 'db4', 'db8', 'sym4', 'coif2'}
    assert {n for _, n in sweep} == {1, 2, 3, 4, 5}
    for entry in entries:
        if entry.enhancer is not None:
            assert MODELS.get(entry.enhancer['type']) is not None
    assert len(set(grid.seeds)) >= 2


def test_full_grid_crosses_wavelets_and_levels():
    grid, entries = runner.load_grid(GRID_FULL)
    assert wgse_sweep(entries) == {(w, n)
                                   for w in ('db1', 'db4', 'db8', 'sym4',
                                             'coif2') for n in range(1, 6)}
    assert grid.cfg_options.num_steps == 129 and grid.epochs == 100
    assert len(entries) == 2 * 32


@pytest.mark.parametrize('name', ['segformer_b0_raw', 'segformer_b0_tfi',
                                  'segformer_b0_wgse3d',
                                  'pspnet_wgse1d_db4_l5',
                                  'pspnet_mean_spatial'])
def test_entry_options_survive_the_command_line(name):
    grid, entries = runner.load_grid(GRID_CPU)
    entry, = runner.select(entries, [name])
    options = dict(grid.cfg_options, data_root='/data/x',
                   **runner.enhancer_options(entry.enhancer))
    parser = argparse.ArgumentParser()
    add_runner_arguments(parser)
    args = parser.parse_args(['--cfg-options', *runner.as_cli(options)])
    cfg = load_config(entry.config, args.cfg_options)
    assert cfg.model.data_preprocessor.enhancer == entry.enhancer
    assert cfg.model.backbone.in_channels == grid.cfg_options.num_steps
    assert cfg.train_dataloader.dataset.data_root == '/data/x'
    assert tuple(cfg.crop_size) == (64, 128)


def cfg_of(grid, entry):
    """The config a run of ``entry`` trains, through the command line."""
    run, = runner.plan([entry], ExperimentSettings(
        GRID_CPU, '/data/x', '/tmp/w', seeds=[0], max_iters=10), grid)
    parser = argparse.ArgumentParser()
    add_runner_arguments(parser)
    args = parser.parse_args(['--cfg-options',
                              *runner.as_cli(run.train_options)])
    return load_config(entry.config, args.cfg_options)


def test_converged_grid_has_the_comparison_and_the_ablations():
    register_all_modules()
    grid, entries = runner.load_grid(GRID_CONVERGED)
    by_name = {e.name: e for e in entries}
    for model in ('segformer_b0', 'pspnet_r18'):
        for name in ('raw', 'tfp', 'tfi', 'mean_spatial', 'mean_temporal',
                     'wgse1d', 'wgse2d', 'wgse3d', 'wgse1d_long', 'trcnn',
                     'wgse1d_lr10', 'wgse1d_lowpass_init', 'wgse1d_norm',
                     'wgse1d_w16', 'wgse1d_w8'):
            entry = by_name[f'{model}_{name}']
            if entry.enhancer is not None:  # each builds
                MODELS.build(entry.enhancer)
    assert by_name['pspnet_r18_trcnn'].enhancer['wavelet'] is None
    assert by_name['pspnet_r18_wgse1d_long'].enhancer['num_blocks'] == 2

    cfg = cfg_of(grid, by_name['pspnet_r18_wgse1d_lr10'])
    assert cfg.model.backbone.depth == 18
    assert cfg.model.backbone.in_channels == 41
    assert cfg.model.decode_head.in_channels == 512
    assert cfg.optim_wrapper.paramwise_cfg.custom_keys == dict(
        enhancer=dict(lr_mult=10))
    assert cfg.model.data_preprocessor.enhancer == dict(type='WGSE', dim=1)
    assert tuple(cfg.crop_size) == (32, 64)
    cfg = cfg_of(grid, by_name['segformer_b0_wgse1d_norm'])
    assert 'paramwise_cfg' not in cfg.optim_wrapper
    assert cfg.model.data_preprocessor.enhancer.output_norm is True
    assert cfg.model.backbone.type == 'MixVisionTransformer'


@pytest.mark.parametrize('models, enhancers, match', [
    ("dict(m=dict(config='{c}', extra=1))", 'dict(raw=None)', 'model .m.'),
    ("dict(m=dict(cfg_options=dict()))", 'dict(raw=None)', 'model .m.'),
    ("dict(m='{c}')", "dict(v=dict(enhancer=None, lr=1))", 'enhancer .v.'),
    ("dict(m='{c}')", "dict(v=dict(cfg_options=dict(a=1)))", 'enhancer .v.'),
    ("dict(m='{c}')", "dict(v=dict(enhancer=None, cfg_options={'a': [1]}))",
     'only str'),
    ("['{c}']", 'dict(raw=None)', 'models must be a dict of names'),
    ("dict()", 'dict(raw=None)', 'models must be a dict of names'),
    ("dict(m='{c}')", "['TFP']", 'enhancers must be a dict of names'),
    ("dict(m='{c}')", "dict(tfp='TFP')", r"enhancers\['tfp'\] must be"),
    ("dict(m=3)", 'dict(raw=None)', r"models\['m'\] must be"),
    ("dict(m=dict(config=3))", 'dict(raw=None)', 'config must be a path'),
    ("dict(m='{c}')", "dict(v=dict(enhancer='TFP'))",
     "enhancer 'v' must be None or dict"),
    ("dict(m='{c}')",
     "dict(v=dict(enhancer=None, cfg_options={'a': \"'q'\"}))",
     'would not survive'),
])
def test_malformed_grid_entries_are_named(tmp_path, models, enhancers,
                                          match):
    config = osp.join(ROOT, 'configs', 'segformer_b0_raw.py')
    grid = tmp_path / 'grid.py'
    grid.write_text(f'models = {models.format(c=config)}\n'
                    f'enhancers = {enhancers}\n'
                    "cfg_options = dict(num_steps=9)\nepochs = 1\n"
                    "seeds = [0]\nlatency = dict(repeat=1, warmup=0)\n")
    with pytest.raises((ValueError, TypeError), match=match):
        runner.load_grid(str(grid))


def write_scalars(run_dir, timestamp, records):
    log = run_dir / timestamp / 'vis_data'
    log.mkdir(parents=True)
    (log / 'scalars.json').write_text(''.join(
        json.dumps(r) + '\n' for r in records))


def test_loss_curve_joins_attempts_and_measures_flatness(tmp_path):
    write_scalars(tmp_path, '20260101_000000', [
        dict(loss=4.0, iter=10, lr=1.0), dict(loss=3.0, iter=20),
        dict(loss=9.0, iter=30)])  # the attempt that was interrupted
    write_scalars(tmp_path, '20260101_010000', [
        dict(loss=2.0, iter=30), dict(loss=2.0, iter=40),
        dict(mIoU=50.0, step=40)] + [
        dict(loss=loss, iter=step) for step, loss in
        ((50, 1.5), (60, 1.5), (70, 1.2), (80, 1.2))])
    curve = runner.loss_curve(str(tmp_path))
    assert curve == [[10, 4.0], [20, 3.0], [30, 2.0], [40, 2.0],
                     [50, 1.5], [60, 1.5], [70, 1.2], [80, 1.2]]
    # last quarter (60, 80]: 1.2; the quarter before, (40, 60]: 1.5
    assert math.isclose(runner.loss_change(curve), 1.2 / 1.5 - 1)
    assert runner.loss_change(curve[:3]) is None
    assert runner.loss_change([]) is None
    assert runner.loss_curve(str(tmp_path / 'nothing')) == []


def schedule_cfg(**kwargs):
    options, checkpoint = runner.schedule_options(**kwargs)
    parser = argparse.ArgumentParser()
    add_runner_arguments(parser)
    args = parser.parse_args(['--cfg-options', *runner.as_cli(options)])
    return load_config(osp.join(ROOT, 'configs', 'segformer_b0_raw.py'),
                       args.cfg_options), checkpoint


def test_epoch_schedule_keeps_the_warm_up_shape():
    cfg, checkpoint = schedule_cfg(epochs=20, max_iters=None)
    assert checkpoint == 'epoch_20.pth'
    assert cfg.train_cfg.max_epochs == 20
    warmup, poly = cfg.param_scheduler
    assert (warmup.end, poly.begin, poly.end) == (2, 2, 20)
    assert cfg.val_cfg is None and cfg.val_dataloader is None
    assert cfg.default_hooks.checkpoint.interval == 1
    cfg, _ = schedule_cfg(epochs=1, max_iters=None)
    assert (cfg.param_scheduler[0].end, cfg.param_scheduler[1].end) == (1, 2)


def test_iteration_schedule():
    cfg, checkpoint = schedule_cfg(epochs=None, max_iters=30)
    assert checkpoint == 'iter_30.pth'
    assert cfg.train_cfg == dict(type='IterBasedTrainLoop', max_iters=30)
    assert all(not s.by_epoch for s in cfg.param_scheduler)
    assert (cfg.param_scheduler[0].end, cfg.param_scheduler[1].end) == (3, 30)
    assert not cfg.default_hooks.checkpoint.by_epoch
    assert not cfg.log_processor.by_epoch
    with pytest.raises(ValueError, match='exactly one'):
        runner.schedule_options(epochs=2, max_iters=3)


def test_values_that_would_not_survive_the_command_line_are_refused():
    with pytest.raises(TypeError, match='only str'):
        runner.as_cli({'a': dict(b=1)})
    with pytest.raises(ValueError, match='survive'):
        runner.as_cli({'a': 'None'})


def test_select_by_pattern_and_unknown_names():
    _, entries = runner.load_grid(GRID_CPU)
    chosen = runner.select(entries, ['pspnet_wgse1d_db8_*',
                                     'segformer_b0_raw'])
    assert [e.name for e in chosen] == ['segformer_b0_raw'] + [
        f'pspnet_wgse1d_db8_l{n}' for n in (1, 2, 3, 4)]  # grid order
    with pytest.raises(ValueError, match='matches no entry.*segformer_b0_raw'):
        runner.select(entries, ['resnet_raw'])


def test_runs_made_with_other_settings_are_not_mixed_in(tmp_path):
    grid, entries = runner.load_grid(GRID_CPU)
    settings = ExperimentSettings(GRID_CPU, 'data/x', str(tmp_path),
                                  seeds=[0, 1], epochs=3)
    runs = runner.plan(runner.select(entries, ['segformer_b0_tf?']),
                       settings, grid)
    assert [(r.entry.name, r.seed) for r in runs] == [
        ('segformer_b0_tfp', 0), ('segformer_b0_tfi', 0),
        ('segformer_b0_tfp', 1), ('segformer_b0_tfi', 1)]
    run = runs[0]
    assert run.train_options['randomness.seed'] == 0
    assert run.train_options['train_cfg.max_epochs'] == 3
    assert run.checkpoint == osp.join(run.run_dir, 'epoch_3.pth')
    assert not runner.finished(run)
    write_result(run, run.train_options)
    assert runner.finished(run)
    write_result(run, dict(run.train_options,
                           **{'train_cfg.max_epochs': 5}))
    with pytest.raises(StaleRunError, match='train_cfg.max_epochs differ'):
        runner.finished(run)

    # the tool says so in one line, before it runs or reports anything
    with pytest.raises(SystemExit, match=r'^\S+/segformer_b0_tfp/seed_0/'
                       r'result.json was made with other settings '
                       r'\(train_cfg.max_epochs differ\); use another '
                       r'--work-dir$'):
        cli.main([GRID_CPU, '--data-root', 'data/x', '--work-dir',
                  str(tmp_path), '--seeds', '0', '1', '--epochs', '3',
                  '--only', 'segformer_b0_tf?', '--report-only'])
    assert not (tmp_path / 'results.md').exists()


def write_result(run, train_options):
    """A ``result.json`` of ``run`` made with ``train_options``."""
    path = osp.join(run.run_dir, 'result.json')
    os.makedirs(run.run_dir, exist_ok=True)
    with open(path, 'w') as f:
        json.dump(dict(train_options=train_options), f)


def test_settings_are_checked_once():
    settings = ExperimentSettings(GRID_CPU, 'data/x', 'work', seeds=[2, 0],
                                  max_iters=60, only=['pspnet_*'])
    assert settings.seeds == (2, 0) and settings.only == ('pspnet_*',)
    assert settings.schedule == '60 iterations'
    assert settings.report_to == 'work'
    assert ExperimentSettings(GRID_CPU, 'd', 'w', [0], epochs=1,
                              report_dir='r').report_to == 'r'
    assert ExperimentSettings(GRID_CPU, 'd', 'w', [0],
                              epochs=10).schedule == '10 epochs'
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.seeds = (1,)
    for schedule in (dict(), dict(epochs=2, max_iters=3)):
        with pytest.raises(ValueError, match='exactly one'):
            ExperimentSettings(GRID_CPU, 'd', 'w', [0], **schedule)
    with pytest.raises(ArgumentError, match='ExperimentSettings: epochs '
                       'must be an integer >= 1'):
        ExperimentSettings(GRID_CPU, 'd', 'w', [0], epochs=0)
    with pytest.raises(ArgumentError, match='ExperimentSettings: seeds'):
        ExperimentSettings(GRID_CPU, 'd', 'w', [-1], epochs=1)
    with pytest.raises(ArgumentError, match='ExperimentSettings: seeds'):
        ExperimentSettings(GRID_CPU, 'd', 'w', [], epochs=1)
    with pytest.raises(ValueError,
                       match=r'seeds must not repeat.*\[0, 1, 0\]'):
        ExperimentSettings(GRID_CPU, 'd', 'w', [0, 1, 0], epochs=1)
    with pytest.raises(ArgumentError, match='ExperimentSettings: grid'):
        ExperimentSettings(GRID_CPU + '.missing', 'd', 'w', [0], epochs=1)
    with pytest.raises(ArgumentError, match='ExperimentSettings: only'):
        ExperimentSettings(GRID_CPU, 'd', 'w', [0], epochs=1, only='x*')


def test_the_tool_fills_the_grids_defaults_and_refuses_in_one_line(
        tmp_path):
    grid, _ = runner.load_grid(GRID_CPU)
    args = cli.parse_args([GRID_CPU, '--data-root', 'd', '--work-dir', 'w'])
    settings = cli.settings_from(args, grid)
    assert settings.seeds == tuple(grid.seeds)
    assert (settings.epochs, settings.max_iters) == (grid.epochs, None)
    args = cli.parse_args([GRID_CPU, '--data-root', 'd', '--work-dir', 'w',
                           '--seeds', '5', '--max-iters', '7'])
    settings = cli.settings_from(args, grid)
    assert (settings.seeds, settings.epochs, settings.max_iters) == (
        (5,), None, 7)
    with pytest.raises(SystemExit, match='^run_experiments.py: '
                       'ExperimentSettings: seeds must not repeat'):
        cli.main([GRID_CPU, '--data-root', 'd', '--work-dir',
                  str(tmp_path), '--seeds', '1', '1', '--list'])


def test_the_library_takes_no_namespace_and_exits_nowhere():
    """Library functions get settings, not a command line; a library
    error is an exception the tool turns into its exit."""
    package = osp.join(ROOT, 'wgse_bench', 'experiments')
    for path in (p for name in ('wgse_mmseg', 'wgse_bench') for p in
                 glob.glob(osp.join(ROOT, name, '**', '*.py'),
                           recursive=True)):
        tree = ast.parse(open(path, encoding='utf-8').read())
        for node in ast.walk(tree):
            if isinstance(node, ast.Raise) and node.exc is not None:
                call = node.exc.func if isinstance(node.exc, ast.Call) \
                    else node.exc
                assert getattr(call, 'id', None) != 'SystemExit', (
                    f'{path}:{node.lineno} raises SystemExit')
            if path.startswith(package) and isinstance(
                    node, (ast.Import, ast.ImportFrom)):
                names = [a.name for a in node.names] + [
                    getattr(node, 'module', None) or '']
                assert 'argparse' not in names, f'{path} imports argparse'


def fake_result(path, entry, seed, miou, ms, seconds, loss_curve=None):
    result = dict(name=entry.name, model=entry.model, seed=seed, mIoU=miou,
                  mAcc=miou + 10, aAcc=miou + 20, params=1000,
                  enhancer_params=0, ms_per_image=dict(median=ms),
                  image_size=[64, 128], train_seconds=seconds,
                  loss_curve=loss_curve or [],
                  environment=dict(cpu='test cpu', cpu_count=2,
                                   torch_threads=2, torch='2.x', mmcv='2.1',
                                   mmengine='0.10', mmsegmentation='1.2',
                                   python='3', platform='linux'))
    run_dir = path / entry.name / f'seed_{seed}'
    run_dir.mkdir(parents=True)
    (run_dir / 'result.json').write_text(json.dumps(result))


def test_aggregate_and_report(tmp_path):
    grid, entries = runner.load_grid(GRID_CPU)
    raw, tfp, tfi = runner.select(entries, ['segformer_b0_raw',
                                            'segformer_b0_tfi',
                                            'segformer_b0_tfp'])
    curve = [[10, 2.0], [20, 1.6], [30, 1.4], [40, 1.2], [50, 1.0],
             [60, 1.0], [70, 0.9], [80, 0.9]]
    fake_result(tmp_path, raw, 0, 10.0, 5.0, 60.0, curve)
    fake_result(tmp_path, raw, 1, 14.0, 7.0, 120.0,
                [[s, 2 * loss] for s, loss in curve])
    fake_result(tmp_path, tfi, 0, 20.0, 6.0, 90.0)  # logged no loss
    (tmp_path / raw.name / 'benchmark.json').write_text(json.dumps(dict(
        flops=2.5e9, enhancer_flops=0, train_step_ms=dict(median=123.4),
        memory=dict(peak_mb=456.7))))
    rows = runner.aggregate([raw, tfi, tfp], [0, 1], str(tmp_path))
    assert [r['name'] for r in rows] == ['segformer_b0_raw',
                                         'segformer_b0_tfi']
    assert rows[0]['mIoU_mean'] == 12.0
    assert math.isclose(rows[0]['mIoU_std'], math.sqrt(8))
    assert rows[0]['ms_per_image_mean'] == 6.0 and rows[0]['seeds'] == 2
    assert rows[1]['mIoU_std'] is None and rows[1]['enhancer'] == 'TFI()'
    # final loss: the mean over iterations > 60 (0.9 and 1.8); change: the
    # last quarter against (40, 60] (1.0 and 2.0): -10 % for both seeds
    assert math.isclose(rows[0]['final_loss_mean'], 1.35)
    assert math.isclose(rows[0]['loss_change_mean'], -0.1)
    assert rows[1]['final_loss_mean'] is None
    assert rows[1]['benchmark'] is None

    runner.write_csv(rows, str(tmp_path / 'results.csv'))
    with open(tmp_path / 'results.csv') as f:
        table = list(csv.DictReader(f))
    assert table[0]['aAcc_mean'] == '32.0' and table[1]['mIoU_std'] == ''
    assert list(table[0]) == runner.CSV_COLUMNS
    assert (table[0]['gflops'], table[0]['train_step_ms'],
            table[0]['train_memory_mb']) == ('2.5', '123.4', '456.7')
    assert table[1]['gflops'] == '' and table[1]['loss_change_mean'] == ''

    settings = ExperimentSettings(GRID_CPU, 'data/x', str(tmp_path),
                                  seeds=[0, 1], epochs=3)
    runner.write_markdown(rows, str(tmp_path / 'results.md'), 'python cmd',
                          settings, grid, 'plot.png')
    text = (tmp_path / 'results.md').read_text()
    assert '```bash\npython cmd\n```' in text
    assert '3 epochs, seeds 0 1' in text and 'test cpu' in text
    assert 'trained for 4.5 min in all' in text  # 60 + 120 + 90 s
    assert 'at a 1-minute load average of ' in text
    assert '| segformer_b0_raw | none     |     2 | 12.00 ± 2.83 |' in text
    raw_line = next(line for line in text.splitlines()
                    if line.startswith('| segformer_b0_raw'))
    assert [c.strip() for c in raw_line.strip('|').split('|')][-5:] == [
        '1.35 ± 0.64', '-10.0 ± 0.0', '2.50', '123', '457']
    assert '![mIoU against ms per image](plot.png)' in text
    assert '![Training loss curves](loss_curves.png)' in text

    pytest.importorskip('matplotlib')
    runner.plot(rows, str(tmp_path / 'plot.png'))
    assert (tmp_path / 'plot.png').read_bytes()[:4] == b'\x89PNG'
    runner.plot_loss_curves(rows, str(tmp_path / 'loss.png'))
    assert (tmp_path / 'loss.png').read_bytes()[:4] == b'\x89PNG'
    # runs shorter than the logger's interval: the panel says so, and
    # matplotlib has nothing to warn about
    import warnings
    for row in rows:
        row['loss_curves'] = [[]]
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        runner.plot_loss_curves(rows, str(tmp_path / 'empty.png'))


def _deployment_file(path, speeds):
    """A JSON file as benchmark_deployment.py writes it: name -> (torch,
    onnxruntime) windows per second."""
    env = dict(cpu='test cpu', cpu_count=2, torch_threads=2, torch='2.x',
               onnxruntime='1.x', load_average=0.5)
    results = [dict(name=name, shape=[41, 128, 256], batch_size=1,
                    environment=env,
                    torch_eager=dict(windows_per_s=eager),
                    onnxruntime=dict(windows_per_s=onnx))
               for name, (eager, onnx) in speeds.items()]
    path.write_text(json.dumps(dict(results=results, failed=[])))
    return str(path)


def test_report_gains_the_deployment_columns(tmp_path):
    """With --deployment, the CSV, the table and the plot gain windows per
    second in torch and ONNX Runtime; an entry not measured reads '-'."""
    grid, entries = runner.load_grid(GRID_CPU)
    raw, tfi = runner.select(entries, ['segformer_b0_raw',
                                       'segformer_b0_tfi'])
    work = tmp_path / 'work'
    fake_result(work, raw, 0, 10.0, 5.0, 60.0)
    fake_result(work, tfi, 0, 20.0, 6.0, 90.0)
    deployment = _deployment_file(tmp_path / 'deployment.json',
                                  {'segformer_b0_raw': (3.25, 7.5)})
    settings = ExperimentSettings(GRID_CPU, 'data/x', str(work), seeds=[0],
                                  epochs=3, report_dir=str(tmp_path / 'r'),
                                  deployment=deployment)
    rows = runner.report([raw, tfi], settings, grid, 'python cmd')
    assert rows[0]['deployment']['onnxruntime'] == 7.5
    assert rows[1]['deployment'] is None
    with open(tmp_path / 'r' / 'results.csv') as f:
        table = list(csv.DictReader(f))
    assert (table[0]['torch_windows_per_s'],
            table[0]['onnxruntime_windows_per_s']) == ('3.25', '7.5')
    assert table[1]['torch_windows_per_s'] == ''
    text = (tmp_path / 'r' / 'results.md').read_text()
    header = next(line for line in text.splitlines()
                  if line.startswith('| entry'))
    assert [c.strip() for c in header.strip('|').split('|')][-2:] == [
        'windows/s torch', 'windows/s ONNX Runtime']
    cells = {line.split('|')[1].strip(): [
        c.strip() for c in line.strip('|').split('|')][-2:]
        for line in text.splitlines() if line.startswith('| segformer')}
    assert cells == {'segformer_b0_raw': ['3.25', '7.50'],
                     'segformer_b0_tfi': ['-', '-']}
    assert 'onnxruntime 1.x; 1-minute load average 0.5' in text
    assert (tmp_path / 'r' / 'accuracy_vs_time.png').read_bytes()[:4] == \
        b'\x89PNG'
    # without the file: neither columns nor note
    plain = ExperimentSettings(GRID_CPU, 'data/x', str(work), seeds=[0],
                               epochs=3, report_dir=str(tmp_path / 'p'))
    runner.report([raw, tfi], plain, grid, 'python cmd')
    text = (tmp_path / 'p' / 'results.md').read_text()
    assert 'windows/s' not in text
    # a file that is not one, named
    bad = tmp_path / 'bad.json'
    bad.write_text('{"results": [{"name": "x"}]}')
    with pytest.raises(ValueError, match='bad.json: not a JSON file of '
                       'benchmark_deployment.py'):
        runner.read_deployment(str(bad))


@pytest.mark.long(45)
def test_tiny_grid_end_to_end_and_resume(tmp_path, capsys):
    """The command as a user runs it, then (in this process, the same
    ``main``) run again, and a report over more than has run."""
    data = tmp_path / 'data'
    make_synthetic_dataset(str(data), num_train=4, num_val=2, height=32,
                           width=64, num_steps=9, progress=False)
    grid = tmp_path / 'grid.py'
    grid.write_text(f"_base_ = [{GRID_CPU!r}]\n"
                    "cfg_options = dict(num_steps=9, crop_size='32,64')\n"
                    "latency = dict(repeat=1, warmup=0)\n")
    work, report = tmp_path / 'work', tmp_path / 'report'
    command = [sys.executable, RUNNER, str(grid), '--data-root', str(data),
               '--work-dir', str(work), '--seeds', '0', '--max-iters', '1',
               '--only', 'segformer_b0_tfi', '--report-dir', str(report)]
    proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert '[1/1] segformer_b0_tfi seed 0: mIoU' in proc.stdout
    run_dir = work / 'segformer_b0_tfi' / 'seed_0'
    result = json.loads((run_dir / 'result.json').read_text())
    assert result['enhancer'] == dict(type='TFI')
    assert all(0 <= result[m] <= 100 for m in ('mIoU', 'mAcc', 'aAcc'))
    assert result['ms_per_image']['median'] > 0
    assert result['image_size'] == [32, 64] and result['train_attempts'] == 1
    assert result['loss_curve'] == [[1, pytest.approx(
        result['loss_curve'][0][1])]] and result['loss_curve'][0][1] > 0
    assert not list(run_dir.glob('*.pth'))  # removed once done
    for name in ('results.md', 'results.csv', 'accuracy_vs_time.png'):
        assert (report / name).exists()

    arguments = command[2:]  # after python and the script
    capsys.readouterr()
    assert cli.main(arguments) == 0
    assert 'done before, skipped' in capsys.readouterr().out
    assert json.loads((run_dir / 'result.json').read_text()) == result
    # --cfg-options reach every run: a finished run made without them is
    # not mixed in
    with pytest.raises(SystemExit, match=r'made with other settings \('
                       r'train_dataloader\.batch_size differ\)'):
        cli.main(arguments + ['--cfg-options',
                              'train_dataloader.batch_size=2'])

    # a report over more entries and seeds than have run trains nothing,
    # and needs no dataset (reporting where the data is not)
    data.rename(tmp_path / 'data_moved')
    assert cli.main(arguments[:arguments.index('--seeds')] + [
        '--seeds', '0', '1', '--max-iters', '1', '--only',
        'segformer_b0_tfi', 'segformer_b0_raw', '--report-dir',
        str(report), '--report-only', '--benchmark']) == 0
    printed = capsys.readouterr().out
    assert 'segformer_b0_raw seed 0: not run (--report-only)' in printed
    assert 'segformer_b0_tfi seed 1: not run (--report-only)' in printed
    assert not (work / 'segformer_b0_raw').exists()
    assert not (work / 'segformer_b0_tfi' / 'seed_1').exists()
    # the benchmark measured the entry that has a run, once
    measured = json.loads((work / 'segformer_b0_tfi' /
                           'benchmark.json').read_text())
    assert measured['crop'] == [32, 64] and measured['num_steps'] == 9
    assert measured['memory']['peak_mb'] > 0 and measured['flops'] > 0
    assert 'benchmark segformer_b0_tfi: ' in printed
    assert not (work / 'segformer_b0_raw' / 'benchmark.json').exists()
    with open(report / 'results.csv') as f:
        rows = list(csv.DictReader(f))
    assert [(r['name'], r['seeds']) for r in rows] == [
        ('segformer_b0_tfi', '1')]


def test_a_run_another_process_runs_is_not_run_twice(tmp_path, capsys,
                                                     monkeypatch):
    """Two grid commands at once: a run whose folder another process owns
    is reported failed, naming it, and not trained a second time."""
    from wgse_mmseg.fileio.locks import own_folder
    (tmp_path / 'data' / 'spike' / 'train').mkdir(parents=True)
    grid, entries = runner.load_grid(GRID_CPU)
    settings = ExperimentSettings(GRID_CPU, str(tmp_path / 'data'),
                                  str(tmp_path / 'work'), seeds=[0],
                                  epochs=1)
    run, = runner.plan(runner.select(entries, ['segformer_b0_tfp']),
                       settings, grid)
    started = []
    monkeypatch.setattr(runner, 'run_one', lambda *args: started.append(args))
    monkeypatch.setattr(runner, 'report', lambda *args: None)
    with own_folder(run.run_dir):
        code = cli.main([GRID_CPU, '--data-root', str(tmp_path / 'data'),
                         '--work-dir', str(tmp_path / 'work'), '--seeds',
                         '0', '--epochs', '1', '--only', 'segformer_b0_tfp'])
    printed = capsys.readouterr().out
    assert code == 1 and started == []
    assert 'segformer_b0_tfp seed 0: FAILED' in printed
    assert f'another process is writing this output (process ' \
        f'{os.getpid()}' in printed


def test_the_time_left_is_the_mean_run_times_the_runs_left():
    assert cli.time_left([], 3) == ''
    assert cli.time_left([10.0, 20.0], 0) == ''
    assert cli.time_left([10.0, 20.0], 2) == ', about 30 s left'
    assert cli.time_left([100.0, 140.0], 3) == ', about 6 min left'


def test_only_the_runs_own_checkpoints_are_removed(tmp_path):
    """A run's folder after training: the checkpoints its training wrote
    (in the manifest) go, with ``last_checkpoint`` naming one; a ``.pth``
    the user put there stays."""
    from wgse_mmseg.fileio.atomic import write_bytes
    from wgse_mmseg.fileio.locks import own_folder
    from wgse_bench.experiments.runner import _remove_checkpoints
    run_dir = tmp_path / 'seed_0'
    with own_folder(str(run_dir)):
        with own_folder(str(run_dir), job='train', claim=False):
            write_bytes(str(run_dir / 'iter_1.pth'), b'weights')
        (run_dir / 'last_checkpoint').write_text(str(run_dir / 'iter_1.pth'))
        (run_dir / 'mine.pth').write_bytes(b'the user\'s')
        _remove_checkpoints(str(run_dir))
    assert sorted(os.listdir(run_dir)) == ['.wgse-output', 'mine.pth']
