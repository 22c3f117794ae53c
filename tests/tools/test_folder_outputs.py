"""The tools' folder outputs hold only what the package wrote, and an
output that is a FIFO is streamed to or refused, never replaced: the
command lines in-process, on the cases a user meets."""
import os
import os.path as osp

import numpy as np
import pytest

from wgse_mmseg.fileio.spike_files import save_spikes


def _recording(path):
    rng = np.random.default_rng(0)
    save_spikes(path, (rng.random((120, 8, 12)) < 0.3).astype(np.uint8))
    return path


def test_reconstruct_walk_refuses_a_recording_in_its_frames_folder(
        tmp_path, load_tool, capsys):
    """``reconstruct.py D/walk_frames/rec.npy --out D/walk.gif --stride 20
    --save-frames``: refused naming both, the recording kept."""
    frames = tmp_path / 'walk_frames'
    frames.mkdir()
    path = _recording(str(frames / 'rec.npy'))
    before = open(path, 'rb').read()
    tool = load_tool('tools/misc/reconstruct.py')
    with pytest.raises(SystemExit) as stop:
        tool.main([path, '--out', str(tmp_path / 'walk.gif'), '--stride',
                   '20', '--save-frames', '--method', 'tfp',
                   '--num-steps', '9'])
    assert f'walk_frames: this output folder holds the input {path}' in \
        str(stop.value.code)
    assert open(path, 'rb').read() == before
    assert sorted(os.listdir(tmp_path)) == ['walk_frames']
    # a user's notes in a frames folder it did not make: refused too
    os.rename(path, tmp_path / 'rec.npy')
    os.rename(path + '.json', tmp_path / 'rec.npy.json')
    (frames / 'notes.txt').write_text('mine')
    with pytest.raises(SystemExit) as stop:
        tool.main([str(tmp_path / 'rec.npy'), '--out',
                   str(tmp_path / 'walk.gif'), '--stride', '20',
                   '--save-frames', '--method', 'tfp', '--num-steps', '9'])
    assert 'walk_frames: an existing folder this package did not make' in \
        str(stop.value.code)
    assert os.listdir(frames) == ['notes.txt']
    os.remove(frames / 'notes.txt')
    tool.main([str(tmp_path / 'rec.npy'), '--out', str(tmp_path / 'walk.gif'),
               '--stride', '20', '--save-frames', '--method', 'tfp',
               '--num-steps', '9'])
    assert sorted(n for n in os.listdir(frames) if n.endswith('.png'))
    assert osp.isfile(tmp_path / 'walk.gif')


def test_a_converter_refuses_an_output_folder_holding_its_input(
        tmp_path, load_tool, monkeypatch):
    """``spike_cityscapes.py OUT/data/cityscapes OUT``: the output folder
    holds the input root (two folders down): refused naming both before
    any work, nothing written; a folder of the user's files refused."""
    out = tmp_path / 'out'
    root = out / 'data' / 'cityscapes'
    (root / 'leftImg8bit').mkdir(parents=True)
    tool = load_tool('tools/dataset_converters/spike_cityscapes.py')
    monkeypatch.setattr('sys.argv', ['spike_cityscapes.py', str(root),
                                     str(out)])
    with pytest.raises(SystemExit) as stop:
        tool.main()
    assert f'{out}: this output folder holds the input {root}' in str(
        stop.value.code)
    assert os.listdir(out) == ['data']
    other = tmp_path / 'cityscapes'
    other.mkdir()
    monkeypatch.setattr('sys.argv', ['spike_cityscapes.py', str(other),
                                     str(out)])
    with pytest.raises(SystemExit) as stop:
        tool.main()
    assert 'out: an existing folder this package did not make (it holds ' \
        'data' in str(stop.value.code)
    assert os.listdir(out) == ['data']


def test_reconstruct_writes_its_images_into_a_folder_it_owns(tmp_path,
                                                             load_tool):
    """Without ``--stride``, ``--out`` is a folder of PNGs: one holding
    the recording, or files of the user's, is refused before any work; a
    new one is made, and taken again by the next run."""
    path = _recording(str(tmp_path / 'rec.npy'))
    tool = load_tool('tools/misc/reconstruct.py')
    argv = ['--method', 'tfp', '--num-steps', '9']
    with pytest.raises(SystemExit) as stop:
        tool.main([path, '--out', str(tmp_path)] + argv)
    assert f'holds the input {path}' in str(stop.value.code)
    assert sorted(os.listdir(tmp_path)) == ['rec.npy', 'rec.npy.json']
    out = tmp_path / 'out'
    tool.main([path, '--out', str(out)] + argv)
    tool.main([path, '--out', str(out), '--frames', '20,30'] + argv)
    assert sorted(n for n in os.listdir(out) if n.endswith('.png')) == [
        'rec_20.png', 'rec_30.png', 'rec_60.png']
    mine = tmp_path / 'mine'
    mine.mkdir()
    (mine / 'notes.txt').write_text('mine')
    with pytest.raises(SystemExit) as stop:
        tool.main([path, '--out', str(mine)] + argv)
    assert 'mine: an existing folder this package did not make' in str(
        stop.value.code)
    assert os.listdir(mine) == ['notes.txt']
