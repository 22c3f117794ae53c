"""Every tool's command line on bad input: a one-line error that names the
argument or the file and what was expected (``SystemExit`` with a message),
never a traceback."""
import io
import os
import os.path as osp
import runpy
import sys
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

from wgse_mmseg.fileio.spike_files import save_spikes

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'configs', 'segformer_b0_wgse.py')


@pytest.fixture(scope='module')
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('cli')
    save_spikes(str(tmp / 'ok.npy'),
                (np.random.default_rng(0).random((50, 8, 12)) < 0.3).astype(
                    np.uint8))
    (tmp / 'text.spk').write_text('hello')
    (tmp / 'notes.pth').write_text('not a checkpoint')
    (tmp / 'empty.npy').write_bytes(b'')
    (tmp / 'mydata').mkdir()  # what a value that lost its space would name
    return tmp


def _run(tool, args, monkeypatch):
    monkeypatch.setattr(sys, 'argv', [tool] + args)
    err = io.StringIO()
    with pytest.raises(SystemExit) as info, redirect_stderr(err), \
            redirect_stdout(io.StringIO()):
        runpy.run_path(osp.join(ROOT, tool if tool.startswith('dev/') else
                                osp.join('tools', tool)),
                       run_name='__main__')
    assert info.value.code != 0
    message = (info.value.code if isinstance(info.value.code, str) else
               err.getvalue())
    assert 'Traceback' not in err.getvalue()
    return message


CASES = [
    ('misc/reconstruct.py', ['{t}/missing.npy', '--out', '{t}/o', '--method',
                             'tfp'], '{t}/missing.npy: no such spike file'),
    ('misc/reconstruct.py', ['{t}/text.spk', '--out', '{t}/o'],
     '{t}/text.spk: 5 bytes is shorter than the 32-byte .spk header'),
    ('misc/reconstruct.py', ['{t}/empty.npy', '--out', '{t}/o', '--method',
                             'tfp'], '{t}/empty.npy: cannot read the array'),
    ('misc/reconstruct.py', ['{t}', '--out', '{t}/o'],
     "unknown spike file extension ''"),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/o', '--num-steps',
                             '0', '--method', 'tfp'],
     'argument --num-steps: must be an integer >= 1'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/o', '--height', '-3',
                             '--width', '4'],
     'argument --height: must be an integer >= 1'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/o', '--frames',
                             '-5', '--method', 'tfp'],
     'centred on frame -5 does not fit'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/o', '--checkpoint',
                             '{t}/notes.pth'],
     '{t}/notes.pth: not a readable checkpoint'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/o', '--checkpoint',
                             '{t}/missing.pth'],
     '{t}/missing.pth: no such checkpoint'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/ok.npy', '--method',
                             'tfp'], '{t}/ok.npy: this output is the input'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/o', '--exposure',
                             'dim'],
     "argument --exposure: must be one of ['auto', 'none'], or a finite"),
    ('dataset_converters/make_synthetic_dataset.py',
     ['{t}/syn', '--num-train', '-1'],
     'argument --num-train: must be an integer >= 0'),
    ('dataset_converters/make_synthetic_dataset.py',
     ['{t}/syn', '--height', '0'],
     'argument --height: must be an integer >= 1'),
    ('dataset_converters/make_synthetic_dataset.py',
     ['{t}/syn', '--threshold', 'nan'],
     'argument --threshold: must be a finite number > 0'),
    ('dataset_converters/spike_cityscapes.py', ['{t}/none', '{t}/out'],
     '{t}/none/leftImg8bit/train: missing'),
    ('dataset_converters/spike_cityscapes.py', ['{t}', '{t}/out', '--height',
                                                '0'],
     'argument --height: must be an integer >= 1'),
    ('dataset_converters/spike_cityscapes.py', ['{t}', '{t}/out',
                                                '--threshold', 'nan'],
     'argument --threshold: must be a finite number > 0'),
    ('dataset_converters/spike_cityscapes.py', ['{t}', '{t}/out', '--seed',
                                                '-4'],
     'argument --seed: must be an integer >= 0'),
    ('dataset_converters/spike_cityscapes.py', ['{t}', '{t}/out', '--scene',
                                                '{{bad json'],
     'is neither a file nor inline JSON'),
    ('dataset_converters/spike_cityscapes.py', ['{t}', '{t}/out', '--nproc',
                                                '0'],
     'argument --nproc: must be an integer >= 1'),
    ('analysis_tools/benchmark_wgse.py', ['--shapes', '1x0x3x4'],
     'argument --shapes: must be (B, T, H, W): B an integer >= 1'),
    ('analysis_tools/benchmark_wgse.py', ['--repeat', '0'],
     'argument --repeat: must be an integer >= 1'),
    ('analysis_tools/benchmark_simulator.py', ['--repeat', '-1'],
     'argument --repeat: must be an integer >= 1'),
    ('analysis_tools/benchmark_simulator.py', ['--steps', '1e8'],
     "argument --steps: must be an integer >= 1 and <= 4096, got '1e8'"),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/o', '--frames',
                             '1.5,"\\'], 'argument --frames: must be'),
    ('train.py', ['{t}/missing.py'], '{t}/missing.py'),
    ('train.py', [CONFIG, '--cfg-options', 'num_steps=0'],
     'argument --cfg-options: num_steps must be an integer >= 1'),
    ('train.py', [CONFIG, '--cfg-options', 'crop_size=abc'],
     'argument --cfg-options: crop_size must be'),
    ('train.py', [CONFIG, '--work-dir', '{t}/work', '--cfg-options',
                  'data_root={t}/none'],
     '{t}/none/spike/train (img_path under data_root'),
    ('test.py', [CONFIG, '{t}/missing.pth', '--work-dir', '{t}/work'],
     '{t}/missing.pth: no such checkpoint'),
    ('test.py', [CONFIG, '{t}/notes.pth', '--work-dir', '{t}/work'],
     '{t}/notes.pth: not a readable checkpoint'),
    ('demo.py', ['{t}/missing.npy', CONFIG, '{t}/missing.pth'],
     '{t}/missing.npy: no such spike file'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/notes.pth', '--cfg-options',
                 'num_steps=9'], '{t}/notes.pth: not a readable checkpoint'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/missing.pth', '--cfg-options',
                 'num_steps=9'], '{t}/missing.pth: no such checkpoint'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/notes.pth', '--opacity', '2'],
     'argument --opacity: must be a finite number >= 0 and <= 1'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/missing.pth', '--stride', '5',
                 '--out-file', '{t}/walk.png'],
     "{t}/walk.png: a walk writes a video, .mp4 or .gif by the extension; "
     "got '.png'"),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/missing.pth', '--stride', '5',
                 '--cfg-options', 'num_steps=9'],
     '{t}/missing.pth: no such checkpoint'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/notes.pth', '--stride', '0'],
     'argument --stride: must be an integer >= 1'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/notes.pth', '--backend', 'trt'],
     "argument --backend: must be one of ['pytorch', 'onnxruntime']"),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/walk.mp4',
                             '--method', 'tfp', '--stride', '100'],
     '{t}/ok.npy: no window of length=41 readouts centred on a multiple of '
     'stride=100 fits in the recording\'s 50 readouts; a stride of at most '
     '10 reaches a centre that fits'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/walk.mp4',
                             '--method', 'tfp', '--num-steps', '60',
                             '--stride', '5'],
     'recording\'s 50 readouts; the longest window it holds is 50 readouts'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/o', '--method',
                             'tfp', '--num-steps', '51'],
     'none fit: the longest window it holds is 50 frames'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/missing.pth', '--stride', '5',
                 '--out-file', '{t}/walk.gif', '--cfg-options',
                 'num_steps=60'],  # refused before the model is loaded
     'recording\'s 50 readouts; the longest window it holds is 50 readouts'),
    ('train.py', [CONFIG, '--work-dir', '{t}/work', '--cfg-options',
                  'crop_size=16,32', 'num_steps=9'],
     'segformer_b0_wgse.py: crop_size=(16, 32) is below the smallest input '
     'the model takes, 29x29'),
    ('train.py', [CONFIG, '--work-dir', '{t}/work', '--cfg-options',
                  'data_root={t}/my data', 'num_steps=9'],  # kept, refused
     "{t}/my data/spike/train (img_path under data_root='{t}/my data')"),
    ('dev/make_reconstruction_figure.py', ['{t}/ok.npy', '--out',
                                           '{t}/f.png', '--methods', 'tfp',
                                           '--scale', '0.01'],
     '--scale 0.01: makes the 8x12 frames of {t}/ok.npy tiles of 0 pixels'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/walk.mp4',
                             '--stride', '10', '--frames', '25'],
     '--frames and --stride'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/walk.mp4',
                             '--stride', '10', '--batch-size', '0'],
     'argument --batch-size: must be an integer >= 1 and <= 4096'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', '{t}/o', '--height', '8'],
     'error: --height and --width go together'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/notes.pth', '--width', '12'],
     'error: --height and --width go together'),
]


@pytest.mark.parametrize('tool, args, expected', CASES,
                         ids=[f'{c[0]}-{i}' for i, c in enumerate(CASES)])
def test_bad_input_gives_a_one_line_error(tool, args, expected, files,
                                          monkeypatch):
    args = [a.format(t=files) for a in args]
    message = _run(tool, args, monkeypatch)
    assert expected.format(t=files) in message, message


#: (tool, its arguments with OUT where an output goes, the input OUT is)
OUTPUT_OVER_INPUT = [
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/notes.pth', '--out-file', 'OUT'],
     'ok.npy'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/notes.pth', '--out-file', 'OUT'],
     'notes.pth'),
    ('demo.py', ['{t}/ok.npy', CONFIG, '{t}/notes.pth', '--stride', '5',
                 '--out-file', 'OUT'], 'ok.npy'),
    ('deployment/pytorch2onnx.py', [CONFIG, '{t}/notes.pth', '--shape', '41',
                                    '8', '12', '--no-verify', '--out',
                                    'OUT'], 'notes.pth'),
    ('misc/reconstruct.py', ['{t}/ok.npy', '--out', 'OUT', '--method', 'tfp'],
     'ok.npy'),
    ('dev/make_reconstruction_figure.py', ['{t}/ok.npy', '--out', 'OUT',
                                           '--methods', 'tfp'], 'ok.npy'),
    ('dataset_converters/spike_cityscapes.py', ['{t}/city', 'OUT'], 'city'),
    ('test.py', [CONFIG, '{t}/notes.pth', '--out', 'OUT'], 'notes.pth'),
]


@pytest.mark.parametrize('link', [False, True], ids=['same', 'hard-link'])
@pytest.mark.parametrize('tool, args, source', OUTPUT_OVER_INPUT,
                         ids=[f'{c[0]}-{c[2]}' for c in OUTPUT_OVER_INPUT])
def test_no_tool_writes_its_output_over_its_input(tool, args, source, link,
                                                  files, monkeypatch):
    """The output named as an input, or as a hard link to it (a folder
    cannot have one), is refused before any work, naming both; the input
    is unchanged."""
    (files / 'city').mkdir(exist_ok=True)
    path = files / source
    out = path
    if link and path.is_file():
        out = files / f'alias-{source}-{tool.replace("/", "-")}.mp4'
        if not out.exists():
            os.link(path, out)
    before = path.read_bytes() if path.is_file() else None
    args = [str(out) if a == 'OUT' else a.format(t=files) for a in args]
    message = _run(tool, args, monkeypatch)
    assert f'{out}: this output is the input' in message, message
    assert str(path) in message
    assert before is None or path.read_bytes() == before


def test_the_figure_tool_pairs_height_and_width(load_tool, files, capsys):
    """The maintainers' figure tool shares the same check (written once,
    ``command_line.check_frame_size``)."""
    tool = load_tool('dev/make_reconstruction_figure.py')
    with pytest.raises(SystemExit) as info:
        tool.parse_args([str(files / 'ok.npy'), '--out',
                         str(files / 'fig.png'), '--height', '8'])
    assert info.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1].endswith(
        'error: --height and --width go together')


@pytest.mark.parametrize('room', ['tools', 'dev'])
def test_every_tool_is_at_most_300_lines(room):
    """A tool is a thin command line; what it needs beyond that belongs in
    the package, once."""
    long = {}
    for folder, _, names in os.walk(osp.join(ROOT, room)):
        for name in names:
            if name.endswith(('.py', '.sh')):
                path = osp.join(folder, name)
                with open(path, encoding='utf-8') as f:
                    lines = sum(1 for _ in f)
                if lines > 300:
                    long[osp.relpath(path, ROOT)] = lines
    assert not long, long
