"""A recording stored (T, H, W) and the same one stored (H, W, T), as other
tools write them, read identically through the pipeline's loader, the
reconstruction tools and benchmark, and the demo's pipeline, given each
file's layout; without one, an array that does not record its layout is an
error that names the file and says how to pass it."""
import os
import os.path as osp

import cv2
import numpy as np
import pytest

import wgse_mmseg
from mmengine.registry import init_default_scope
from mmseg.registry import TRANSFORMS
from wgse_mmseg.core.spike_formats import SpikeFileError
from wgse_mmseg.fileio.images import to_uint8
from wgse_mmseg.core.reconstruction_baselines import tfp
from wgse_mmseg.utils.config import load_config

wgse_mmseg.register_all_modules()

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
STEPS, HEIGHT, WIDTH = 45, 16, 24  # SSIM (the benchmark) needs 11x11


def _clip(seed=0):
    rng = np.random.default_rng(seed)
    rates = rng.random((HEIGHT, WIDTH)) * 0.6
    return (rng.random((STEPS, HEIGHT, WIDTH)) < rates).astype(np.uint8)


def _write(path, clip, layout):
    """``clip`` ``(T, H, W)`` stored in ``layout`` by NumPy alone (as
    another tool writes it: no layout recorded)."""
    stored = clip if layout == 'THW' else clip.transpose(1, 2, 0)
    if path.endswith('.npy'):
        np.save(path, stored)
    else:
        np.savez_compressed(path, spikes=stored)
    return path


@pytest.fixture(params=['.npy', '.npz'])
def both_ways(request, tmp_path):
    """``{layout: path}`` of the same clip written both ways, and it."""
    clip = _clip()
    folder = tmp_path / 'clips'
    folder.mkdir()
    return {layout: _write(str(folder / f'{layout}{request.param}'), clip,
                           layout)
            for layout in ('THW', 'HWT')}, clip


def test_load_spike_from_file_reads_both_layouts(both_ways):
    paths, clip = both_ways
    for layout, path in paths.items():
        loader = TRANSFORMS.build(dict(type='LoadSpikeFromFile',
                                       num_steps=41, layout=layout))
        img = loader(dict(img_path=path))['img']
        assert img.shape == (HEIGHT, WIDTH, 41)  # the pipeline's (H, W, T)
        np.testing.assert_array_equal(img, clip[2:43].transpose(1, 2, 0))
        centred = TRANSFORMS.build(dict(
            type='LoadSpikeFromFile', num_steps=21, center=10,
            layout=layout))(dict(img_path=path))['img']
        np.testing.assert_array_equal(centred, clip[:21].transpose(1, 2, 0))
    with pytest.raises(SpikeFileError, match='does not record its layout'):
        TRANSFORMS.build(dict(type='LoadSpikeFromFile'))(
            dict(img_path=paths['HWT']))


def test_reconstruct_tool_reads_both_layouts(both_ways, tmp_path, capsys,
                                             load_tool):
    paths, clip = both_ways
    tool = load_tool('tools/misc/reconstruct.py')
    images = {}
    for layout, path in paths.items():
        out = tmp_path / layout
        tool.main([path, '--out', str(out), '--method', 'tfp', '--frames',
                   '20', '--exposure', 'none', '--layout', layout])
        name = osp.splitext(osp.basename(path))[0]
        images[layout] = cv2.imread(str(out / f'{name}_20.png'),
                                    cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(images['THW'], images['HWT'])
    np.testing.assert_array_equal(images['HWT'], to_uint8(tfp(clip[0:41])))
    with pytest.raises(SystemExit) as exit_:
        tool.main([paths['HWT'], '--out', str(tmp_path / 'no'), '--method',
                   'tfp'])
    message = str(exit_.value.code)
    assert paths['HWT'] in message and '--layout THW or HWT' in message
    assert not (tmp_path / 'no').exists()


def test_figure_tool_reads_both_layouts(both_ways, tmp_path, load_tool):
    paths, _ = both_ways
    tool = load_tool('dev/make_reconstruction_figure.py')
    figures = {}
    for layout, path in paths.items():
        out = str(tmp_path / f'{layout}.png')
        tool.main([path, '--out', out, '--methods', 'tfp,tfi', '--frames',
                   '20,24', '--layout', layout])
        figures[layout] = cv2.imread(out, cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(figures['THW'], figures['HWT'])


def test_reconstruction_benchmark_reads_both_layouts(tmp_path, capsys):
    from wgse_bench import reconstruction
    clip = _clip(1)
    tables = {}
    for layout in ('THW', 'HWT'):
        root = tmp_path / layout
        os.makedirs(root / 'spike')
        os.makedirs(root / 'gt')
        _write(str(root / 'spike' / 's0.npz'), clip, layout)
        cv2.imwrite(str(root / 'gt' / 's0.png'),
                    to_uint8(tfp(clip[2:43])))
        reconstruction.main([str(root), '--methods', 'tfp,tfi',
                             '--spike-suffix', '.npz', '--layout', layout])
        # the table's rows without the time column (the machine line, its
        # load, and mmengine's log lines differ from run to run)
        tables[layout] = [
            line.rstrip(' |').rsplit('|', 1)[0]
            for line in capsys.readouterr().out.splitlines()
            if line.startswith('|')]
    assert tables['THW'] == tables['HWT']
    assert any(line.startswith('| TFP | ') for line in tables['THW'])
    with pytest.raises(SpikeFileError, match='does not record its layout'):
        reconstruction.benchmark(str(tmp_path / 'HWT'), ['tfp'],
                                 spike_suffix='.npz', progress=False)


def test_demo_pipeline_takes_the_layout(both_ways, load_tool):
    paths, clip = both_ways
    demo = load_tool('tools/demo.py')
    cfg = load_config(osp.join(ROOT, 'configs', 'segformer_b0_wgse.py'),
                      dict(num_steps=9))
    init_default_scope(cfg.get('default_scope', 'mmseg'))
    for layout, path in paths.items():
        data = demo.build_pipeline(cfg, layout=layout)(dict(img_path=path))
        np.testing.assert_array_equal(data['inputs'].numpy(), clip[18:27])
    with pytest.raises(SpikeFileError, match='does not record its layout'):
        demo.build_pipeline(cfg)(dict(img_path=paths['THW']))
    parser = demo.build_parser()
    args = parser.parse_args([paths['HWT'], 'c.py', 'w.pth', '--layout',
                              'HWT'])
    assert args.layout == 'HWT'
