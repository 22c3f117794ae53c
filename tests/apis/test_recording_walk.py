"""Walking a recording (wgse_mmseg.apis.recording_walk): the plan against an
enumeration of the grid, the windows against load_spikes, a generated .dat
recording many batches long walked into MP4 and GIF, resuming after an
interruption, refusing mixed settings, and memory bounded by the batch."""
import csv
import json
import os
import shutil
import subprocess
import sys
import tracemalloc

import cv2
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from wgse_mmseg.fileio.images import to_uint8
from wgse_mmseg.fileio.spike_files import load_spikes, save_spikes
from wgse_mmseg.fileio.input_guard import OutputFolderError
from wgse_mmseg.apis.recording_walk import walk_recording
from wgse_mmseg.apis.walk_plan import (WalkError, plan_walk, read_windows,
                                       walk_outputs)
from wgse_mmseg.apis.walk_state import CSV_COLUMNS

HEIGHT, WIDTH = 32, 48
LENGTH, HALF = 41, 20


def _frame_names(folder):
    """The PNGs in a frames folder (beside them: the package's manifest)."""
    return sorted(n for n in os.listdir(folder) if n.endswith('.png'))


def _recording(path, steps, seed=0, height=HEIGHT, width=WIDTH):
    """A random ``.dat`` recording of ``steps`` readouts with its side
    file, written a chunk at a time (never the whole stream in memory)."""
    rng = np.random.default_rng(seed)
    with open(path, 'wb') as f:
        for first in range(0, steps, 1000):
            count = min(1000, steps - first)
            chunk = (rng.random((count, height, width)) < 0.2).astype(
                np.uint8)
            f.write(np.packbits(chunk[:, ::-1].reshape(count, -1), axis=1,
                                bitorder='little').tobytes())
    with open(path + '.json', 'w') as f:
        json.dump(dict(height=height, width=width), f)
    return path


class RateModel:
    """A window model: each window's spike rate ``(B, H, W)``; counts its
    calls and the windows of each."""

    def __init__(self, fail_on_call=None):
        self.batches, self.fail_on_call = [], fail_on_call

    def __call__(self, spikes):
        assert spikes.dtype == torch.float32 and spikes.dim() == 4
        if len(self.batches) == self.fail_on_call:
            raise KeyboardInterrupt  # what Ctrl-C does mid-walk
        self.batches.append(len(spikes))
        return spikes.mean(1)


def rate_frame(window, rate):
    """The frame of a window: its rate as grey."""
    return to_uint8(np.asarray(rate))


def _reference_frame(path, centre):
    """The frame of the window centred on ``centre``, read on its own."""
    window = load_spikes(path, start=centre - HALF, length=LENGTH)
    return to_uint8(window.mean(0, dtype=np.float32))


def _video_frames(path):
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            return frames
        frames.append(frame)


def _rows(path):
    with open(path, newline='') as f:
        return list(csv.DictReader(f))


@settings(max_examples=200)
@given(total=st.integers(1, 300), length=st.integers(1, 60),
       stride=st.integers(1, 80))
def test_plan_is_the_grid_of_centres_whose_window_fits(total, length,
                                                       stride):
    plan = plan_walk(total, length, stride)
    grid = list(range(0, total, stride))
    fits = [c for c in grid
            if c - length // 2 >= 0 and c - length // 2 + length <= total]
    assert list(plan.centres) == fits
    assert list(plan.skipped_start) + list(plan.centres) + \
        list(plan.skipped_end) == grid
    assert all(c - length // 2 < 0 for c in plan.skipped_start)
    assert all(c - length // 2 + length > total for c in plan.skipped_end)


def test_plan_describes_what_it_skips():
    plan = plan_walk(1000, 41, 100)
    assert (plan.centres[0], plan.centres[-1]) == (100, 900)
    assert list(plan.skipped_start) == [0] and not plan.skipped_end
    text = plan.describe()
    assert '9 windows of 41 readouts' in text and '100..900' in text
    assert 'at the start 0, at the end none' in text
    # centres 0..994 every 7: 21 (window from 1) to 973 (to 994 + 20 = 1014
    # > 1000 for 994; 973 - 20 + 41 = 994 <= 1000) fit
    plan = plan_walk(1000, 41, 7)
    assert plan.centres[-1] == 973 and list(plan.skipped_end) == [980, 987,
                                                                  994]
    assert list(plan.skipped_start) == [0, 7, 14]
    assert 'at the start 0, 7, 14, at the end 980, 987, 994' in \
        plan.describe()


@settings(max_examples=30, deadline=None)
@given(stride=st.integers(1, 90), first=st.integers(0, 5),
       count=st.integers(1, 6))
def test_batch_windows_are_the_windows_read_alone(tmp_path_factory, stride,
                                                  first, count):
    path = str(tmp_path_factory.mktemp('rec') / 'rec.dat')
    _recording(path, 700, height=8, width=8)
    plan = plan_walk(700, LENGTH, stride)
    centres = plan.centres[first:first + count]
    if not centres:
        return
    windows = read_windows(path, plan, centres)
    assert windows.shape == (len(centres), LENGTH, 8, 8)
    for window, centre in zip(windows, centres):
        np.testing.assert_array_equal(
            window, load_spikes(path, start=centre - HALF, length=LENGTH))


@pytest.mark.parametrize('extension', ['.mp4', '.gif'])
def test_walk_of_a_recording_many_batches_long(tmp_path, extension):
    path = _recording(str(tmp_path / 'rec.dat'), 4000)
    video = str(tmp_path / 'out' / f'walk{extension}')
    model = RateModel()
    report = walk_recording(path, video, model, rate_frame, LENGTH, 50,
                            batch_size=4, save_frames=True, progress=False)
    # centres 0, 50, ..., 3950: 0 does not fit (its window starts at -20),
    # 3950 does (it ends at 3950 - 20 + 41 = 3971 <= 4000)
    centres = list(range(50, 3951, 50))
    assert list(report.plan.centres) == centres
    assert list(report.plan.skipped_start) == [0]
    assert not report.plan.skipped_end
    assert (report.resumed, report.computed) == (0, len(centres))
    assert model.batches == [4] * 19 + [3]  # 79 windows, 4 a call

    rows = _rows(tmp_path / 'out' / 'walk.csv')
    assert tuple(rows[0]) == CSV_COLUMNS
    assert [int(r['centre']) for r in rows] == centres
    assert [int(r['window']) for r in rows] == list(range(len(centres)))
    assert all(int(r['start']) == int(r['centre']) - HALF and
               int(r['end']) == int(r['start']) + LENGTH for r in rows)
    assert [int(r['batch']) for r in rows] == [i // 4 * 4
                                               for i in range(len(rows))]
    assert all(float(r['time_ms']) >= 0 for r in rows)

    frames = _frame_names(tmp_path / 'out' / 'walk_frames')
    assert frames == [f'{i:06d}.png' for i in range(len(centres))]
    for index in (0, 1, len(centres) - 1):
        saved = cv2.imread(str(tmp_path / 'out' / 'walk_frames' /
                               frames[index]), cv2.IMREAD_GRAYSCALE)
        np.testing.assert_array_equal(
            saved, _reference_frame(path, centres[index]))
    if extension == '.gif':
        with Image.open(video) as gif:
            assert gif.n_frames == len(centres)
            assert gif.size == (WIDTH, HEIGHT)
            gif.seek(len(centres) - 1)
            last = np.asarray(gif.convert('L'))
        np.testing.assert_array_equal(  # a grey palette holds every level
            last, _reference_frame(path, centres[-1]))
    else:
        decoded = _video_frames(video)
        assert len(decoded) == len(centres)
        assert decoded[0].shape == (HEIGHT, WIDTH, 3)
        # lossy codec: close to the frame, far from another window's
        error = np.abs(decoded[-1][..., 0].astype(int) -
                       _reference_frame(path, centres[-1]))
        assert error.mean() < 12
    assert not os.path.exists(video + '.partial')
    assert not [n for n in os.listdir(tmp_path / 'out') if '.tmp-' in n]


def test_resumes_an_interrupted_walk_without_redoing_it(tmp_path):
    path = _recording(str(tmp_path / 'rec.dat'), 3000)
    whole = str(tmp_path / 'whole' / 'walk.mp4')
    walk_recording(path, whole, RateModel(), rate_frame, LENGTH, 30,
                   batch_size=8, save_frames=True, progress=False)

    video = str(tmp_path / 'cut' / 'walk.mp4')
    outputs = walk_outputs(video)
    interrupted = RateModel(fail_on_call=3)
    with pytest.raises(KeyboardInterrupt):
        walk_recording(path, video, interrupted, rate_frame, LENGTH, 30,
                       batch_size=8, save_frames=True, progress=False)
    # complete or absent: nothing but the state folder
    assert sorted(os.listdir(tmp_path / 'cut')) == ['walk.mp4.partial']
    assert len(open(os.path.join(outputs.partial,
                                 'progress.csv')).readlines()) == 24
    model = RateModel()
    report = walk_recording(path, video, model, rate_frame, LENGTH, 30,
                            batch_size=8, save_frames=True, progress=False)
    total = len(report.plan.centres)  # centres 30..2970
    assert (report.resumed, report.computed) == (24, total - 24)
    assert sum(model.batches) == total - 24
    _same_walk(tmp_path / 'whole', tmp_path / 'cut')
    assert _rows(tmp_path / 'whole' / 'walk.csv')[30]['batch'] == \
        _rows(tmp_path / 'cut' / 'walk.csv')[30]['batch'] == '24'


def _same_walk(one, other):
    """Two walks' CSVs (but the times and batches) and frames are the
    same."""
    def rows(folder):
        return [{k: v for k, v in row.items() if k not in ('time_ms',
                                                           'batch')}
                for row in _rows(folder / 'walk.csv')]
    assert rows(one) == rows(other)
    names = _frame_names(one / 'walk_frames')
    assert names == _frame_names(other / 'walk_frames')
    for name in names:
        assert (one / 'walk_frames' / name).read_bytes() == \
            (other / 'walk_frames' / name).read_bytes()
    assert len(_video_frames(one / 'walk.mp4')) == len(names) == \
        len(_video_frames(other / 'walk.mp4'))


def test_resume_redoes_a_torn_row_and_a_missing_frame(tmp_path):
    path = _recording(str(tmp_path / 'rec.dat'), 2000)
    whole = str(tmp_path / 'whole' / 'walk.mp4')
    walk_recording(path, whole, RateModel(), rate_frame, LENGTH, 40,
                   batch_size=5, save_frames=True, progress=False)
    video = str(tmp_path / 'cut' / 'walk.mp4')
    partial = walk_outputs(video).partial
    with pytest.raises(KeyboardInterrupt):
        walk_recording(path, video, RateModel(fail_on_call=4), rate_frame,
                       LENGTH, 40, batch_size=5, save_frames=True,
                       progress=False)
    progress = os.path.join(partial, 'progress.csv')
    lines = open(progress).readlines()
    assert len(lines) == 20
    # killed mid-row, and window 12's PNG lost (rows 12.. are then redone)
    with open(progress, 'a') as f:
        f.write('20,840,8')
    os.remove(os.path.join(partial, '000012.png'))
    report = walk_recording(path, video, RateModel(), rate_frame, LENGTH,
                            40, batch_size=5, save_frames=True,
                            progress=False)
    assert report.resumed == 12
    _same_walk(tmp_path / 'whole', tmp_path / 'cut')
    # the rows say which model call made them: 12-16 the first after resuming
    batches = [int(r['batch']) for r in _rows(tmp_path / 'cut' / 'walk.csv')]
    assert batches[:17] == [0] * 5 + [5] * 5 + [10] * 2 + [12] * 5


def test_refuses_to_mix_walks_of_other_settings(tmp_path):
    path = _recording(str(tmp_path / 'rec.dat'), 1500)
    video = str(tmp_path / 'walk.gif')
    with pytest.raises(KeyboardInterrupt):
        walk_recording(path, video, RateModel(fail_on_call=1), rate_frame,
                       LENGTH, 30, batch_size=4, settings=dict(gain=1),
                       progress=False)
    partial = walk_outputs(video).partial
    state = sorted(os.listdir(partial))
    for stride, options, named in [(60, dict(gain=1), 'stride'),
                                   (30, dict(gain=2), 'settings')]:
        with pytest.raises(WalkError) as info:
            walk_recording(path, video, RateModel(), rate_frame, LENGTH,
                           stride, batch_size=4, settings=options,
                           progress=False)
        message = str(info.value)
        assert partial in message and named in message
        assert 'remove the folder to start over' in message
    assert sorted(os.listdir(partial)) == state  # untouched
    assert not os.path.exists(video)
    # a changed recording is another walk too
    _recording(path, 1500, seed=1)
    os.utime(path, ns=(1, 1))
    with pytest.raises(WalkError, match='mtime_ns'):
        walk_recording(path, video, RateModel(), rate_frame, LENGTH, 30,
                       batch_size=4, settings=dict(gain=1), progress=False)


def test_peak_memory_does_not_grow_with_the_recording(tmp_path, bounded):
    """A 4x longer recording (8000 readouts: 12 MB as read, 49 MB as float)
    peaks within a small bound of the shorter one: the walk holds a batch,
    never the recording."""
    peaks = {}
    for steps in (2000, 8000):
        path = _recording(str(tmp_path / f'rec{steps}.dat'), steps)
        tracemalloc.start()
        with bounded(120, 64 << 20):
            report = walk_recording(
                path, str(tmp_path / f'walk{steps}.mp4'), RateModel(),
                rate_frame, LENGTH, 25, batch_size=8, progress=False)
        peaks[steps] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert len(report.plan.centres) == steps // 25 - 1
    assert peaks[8000] < peaks[2000] * 1.25 + (1 << 20), peaks
    assert peaks[8000] < 8 << 20, peaks


def test_odd_frames_are_padded_for_mp4(tmp_path):
    path = str(tmp_path / 'odd.npy')
    save_spikes(path, (np.random.default_rng(0).random((60, 7, 9)) <
                       0.5).astype(np.uint8))
    video = str(tmp_path / 'odd.mp4')
    walk_recording(path, video, RateModel(), rate_frame, 9, 5,
                   progress=False)
    frames = _video_frames(video)
    assert len(frames) == len(plan_walk(60, 9, 5).centres) == 11
    assert frames[0].shape == (8, 10, 3)


def test_bad_walks_are_named_errors(tmp_path):
    path = _recording(str(tmp_path / 'rec.dat'), 100, height=8, width=8)
    with pytest.raises(WalkError, match=r'walk\.png: a walk writes a video'):
        walk_recording(path, str(tmp_path / 'walk.png'), RateModel(),
                       rate_frame, LENGTH, 10, progress=False)
    # centres 0 and 150 of a 100-readout recording: neither window fits
    with pytest.raises(WalkError) as info:
        walk_recording(path, str(tmp_path / 'walk.mp4'), RateModel(),
                       rate_frame, LENGTH, 150, progress=False)
    assert path in str(info.value) and 'stride=150' in str(info.value)
    assert not os.path.exists(tmp_path / 'walk.mp4.partial')

    def bad_frame(window, rate):
        return np.zeros((2, 2), np.float32)
    with pytest.raises(WalkError, match='8-bit'):
        walk_recording(path, str(tmp_path / 'bad.mp4'), RateModel(),
                       bad_frame, LENGTH, 10, progress=False)
    assert not os.path.exists(tmp_path / 'bad.mp4')


# ------------------------------------------------ the walk owns its state
WALKER = '''
import os, sys, time
import numpy as np
from wgse_mmseg.fileio.images import to_uint8
from wgse_mmseg.apis.recording_walk import walk_recording
recording, video, go = sys.argv[1:4]
print('ready', flush=True)
while not os.path.exists(go):
    time.sleep(0.005)
def model(spikes):
    time.sleep(0.02)
    return spikes.mean(1)
walk_recording(recording, video, model, lambda w, r: to_uint8(np.asarray(r)),
               41, 10, batch_size=2, save_frames=True, progress=False)
'''


def test_two_walks_started_together_give_one_walk(tmp_path):
    """Two processes walking one recording into one video, released at
    the same instant: one walks, the other is refused naming it; the CSV
    holds one walk's rows, and nothing else is left."""
    path = _recording(str(tmp_path / 'rec.dat'), 1200)
    reference = str(tmp_path / 'ref' / 'walk.mp4')
    walk_recording(path, reference, RateModel(), rate_frame, LENGTH, 10,
                   batch_size=2, save_frames=True, progress=False)
    out = tmp_path / 'out'
    go = tmp_path / 'go'
    env = dict(os.environ, PYTHONPATH=os.getcwd(), OMP_NUM_THREADS='1')
    walkers = [subprocess.Popen(
        [sys.executable, '-c', WALKER, path, str(out / 'walk.mp4'), str(go)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        for _ in range(2)]
    for walker in walkers:
        assert walker.stdout.readline().strip() == 'ready'
    go.touch()
    results = [walker.communicate(timeout=600) for walker in walkers]
    codes = sorted(walker.returncode for walker in walkers)
    assert codes[0] == 0 and codes[1] != 0, results
    refused = next(err for walker, (_, err) in zip(walkers, results)
                   if walker.returncode)
    winner = next(walker for walker in walkers if walker.returncode == 0)
    assert 'another process is writing this output' in refused
    assert f'process {winner.pid} on host' in refused
    _same_walk(tmp_path / 'ref', out)
    assert [int(r['window']) for r in _rows(out / 'walk.csv')] == list(
        range(len(plan_walk(1200, LENGTH, 10).centres)))
    assert sorted(os.listdir(out)) == ['walk.csv', 'walk.mp4', 'walk_frames']


def _interrupted(tmp_path, name, fail_on_call=3):
    """A recording, a whole walk of it to ``whole/walk.mp4`` and the state
    of the same walk to ``<name>/walk.mp4`` interrupted after
    ``fail_on_call`` model calls of 5 windows."""
    path = str(tmp_path / 'rec.dat')
    if not os.path.exists(path):
        _recording(path, 1500)
        walk_recording(path, str(tmp_path / 'whole' / 'walk.mp4'),
                       RateModel(), rate_frame, LENGTH, 40, batch_size=5,
                       save_frames=True, progress=False)
    video = str(tmp_path / name / 'walk.mp4')
    with pytest.raises(KeyboardInterrupt):
        walk_recording(path, video, RateModel(fail_on_call=fail_on_call),
                       rate_frame, LENGTH, 40, batch_size=5,
                       save_frames=True, progress=False)
    return path, video, walk_outputs(video).partial


def _resume(path, video):
    return walk_recording(path, video, RateModel(), rate_frame, LENGTH, 40,
                          batch_size=5, save_frames=True, progress=False)


@pytest.mark.parametrize('damage', ['garbage', 'truncated', 'other frame',
                                    'folder', 'link'])
def test_a_damaged_frame_is_made_again(tmp_path, damage):
    """A frame of an interrupted walk damaged in any way (the same size of
    garbage, cut short, another window's valid PNG, a folder, a link) is
    made again with the windows after it: the walk ends as an
    uninterrupted one, at the first re-run."""
    path, video, partial = _interrupted(tmp_path, 'cut')
    frame = os.path.join(partial, '000007.png')
    size = os.path.getsize(frame)
    os.remove(frame)
    if damage == 'garbage':
        with open(frame, 'wb') as f:
            f.write(np.random.default_rng(0).bytes(size))
    elif damage == 'truncated':
        with open(os.path.join(partial, '000008.png'), 'rb') as f:
            data = f.read()
        with open(frame, 'wb') as f:
            f.write(data[:size // 2])
    elif damage == 'other frame':
        shutil.copy(os.path.join(partial, '000008.png'), frame)
    elif damage == 'folder':
        # not the package's: refused naming it, kept, never removed
        os.mkdir(frame)
        (tmp_path / 'cut' / 'walk.mp4.partial' / '000007.png' /
         'mine.txt').write_text('keep me')
        with pytest.raises(OutputFolderError, match='000007.png: a folder'):
            _resume(path, video)
        assert open(os.path.join(frame, 'mine.txt')).read() == 'keep me'
        shutil.rmtree(frame)
    else:
        os.symlink(os.path.join(partial, '000008.png'), frame)
    report = _resume(path, video)
    assert report.resumed == 7
    _same_walk(tmp_path / 'whole', tmp_path / 'cut')


def test_a_linked_progress_file_is_replaced_not_followed(tmp_path):
    """progress.csv made a link to a file outside: that file is neither
    truncated nor appended to, and the walk ends as an uninterrupted one
    (its rows no longer verify: done again)."""
    path, video, partial = _interrupted(tmp_path, 'cut')
    outside = tmp_path / 'precious.csv'
    progress = os.path.join(partial, 'progress.csv')
    shutil.copy(progress, outside)
    before = outside.read_bytes()
    os.remove(progress)
    os.symlink(outside, progress)
    report = _resume(path, video)
    assert report.resumed == 0  # a link is not read: the windows redone
    assert outside.read_bytes() == before
    _same_walk(tmp_path / 'whole', tmp_path / 'cut')
    # a hard link: rewritten as a new file, the other name untouched
    path, video, partial = _interrupted(tmp_path, 'hard')
    progress = os.path.join(partial, 'progress.csv')
    os.remove(outside)
    os.link(progress, outside)
    before = outside.read_bytes()
    _resume(path, video)
    assert outside.read_bytes() == before
    _same_walk(tmp_path / 'whole', tmp_path / 'hard')


@pytest.mark.parametrize('damage', ['garbage', 'link', 'folder', 'missing'])
def test_unreadable_settings_start_the_walk_over(tmp_path, damage):
    path, video, partial = _interrupted(tmp_path, 'cut')
    settings_file = os.path.join(partial, 'settings.json')
    os.remove(settings_file)
    outside = tmp_path / 'outside.json'
    outside.write_text('{"not": "mine"}')
    if damage == 'garbage':
        with open(settings_file, 'w') as f:
            f.write('{"recording": ')
    elif damage == 'link':
        os.symlink(outside, settings_file)
    elif damage == 'folder':
        os.mkdir(settings_file)
        with pytest.raises(OutputFolderError,
                           match='settings.json: a folder'):
            _resume(path, video)
        assert os.path.isdir(settings_file)  # not the package's: kept
        os.rmdir(settings_file)
    report = _resume(path, video)
    assert report.resumed == 0
    assert outside.read_text() == '{"not": "mine"}'
    _same_walk(tmp_path / 'whole', tmp_path / 'cut')


def test_links_at_the_state_folder_and_outputs_are_not_followed(tmp_path):
    """The state folder or the frames folder made a link to a folder
    outside: refused naming it before any work, the link and what it
    leads to kept; the video and the CSV made links to a file outside:
    replaced by the walk's files, the file outside untouched."""
    path = _recording(str(tmp_path / 'rec.dat'), 600)
    outside = tmp_path / 'outside'
    outside.mkdir()
    (outside / 'keep.txt').write_text('keep me')
    out = tmp_path / 'out'
    out.mkdir()
    for name in ('walk.mp4.partial', 'walk_frames'):
        os.symlink(outside, out / name)
        model = RateModel()
        with pytest.raises(OutputFolderError, match=f'{name}: a link or file'):
            walk_recording(path, str(out / 'walk.mp4'), model, rate_frame,
                           LENGTH, 40, batch_size=4, save_frames=True,
                           progress=False)
        assert model.batches == [] and os.path.islink(out / name)
        os.unlink(out / name)
    for name in ('walk.mp4', 'walk.csv'):
        os.symlink(outside / 'keep.txt', out / name)
    walk_recording(path, str(out / 'walk.mp4'), RateModel(), rate_frame,
                   LENGTH, 40, batch_size=4, save_frames=True,
                   progress=False)
    assert sorted(os.listdir(outside)) == ['keep.txt']
    assert (outside / 'keep.txt').read_text() == 'keep me'
    for name in ('walk_frames', 'walk.mp4', 'walk.csv'):
        assert not os.path.islink(out / name)
    assert len(_frame_names(out / 'walk_frames')) == len(
        plan_walk(600, LENGTH, 40).centres)
    (out / 'walk.csv').unlink()
    (out / 'walk.csv').mkdir()
    with pytest.raises(WalkError, match=r'walk\.csv: a folder'):
        walk_recording(path, str(out / 'walk.mp4'), RateModel(), rate_frame,
                       LENGTH, 40, progress=False)


def test_a_video_path_that_is_not_utf8_is_refused_before_the_walk():
    import os
    from wgse_mmseg.apis.walk_plan import walk_outputs
    with pytest.raises(ValueError, match='not UTF-8, which OpenCV cannot'):
        walk_outputs(os.fsdecode(b'/tmp/walk\xff.mp4'))


@pytest.mark.parametrize('folder', ['walk_frames', 'walk.gif.partial',
                                    'walk_frames/deep/er'])
def test_a_recording_inside_the_walks_folders_is_refused_before_any_work(
        tmp_path, folder):
    """The recording inside the frames folder or the state folder (at any
    depth): refused naming both before the model runs; it stays."""
    (tmp_path / folder).mkdir(parents=True)
    path = _recording(str(tmp_path / folder / 'rec.dat'), 300)
    before = open(path, 'rb').read()
    model = RateModel()
    with pytest.raises(OutputFolderError, match='holds the input'):
        walk_recording(path, str(tmp_path / 'walk.gif'), model, rate_frame,
                       LENGTH, 20, save_frames=True, progress=False)
    assert model.batches == []
    assert open(path, 'rb').read() == before
    assert not (tmp_path / 'walk.gif').exists()


def test_a_frames_folder_keeps_the_users_files(tmp_path):
    """An existing frames folder the package did not make is refused
    before any work; one it made, with a file the user added, has its old
    frames replaced by a shorter walk's and keeps the user's file."""
    path = _recording(str(tmp_path / 'rec.dat'), 600)
    frames = tmp_path / 'walk_frames'
    frames.mkdir()
    (frames / 'notes.txt').write_text('mine')
    model = RateModel()
    with pytest.raises(OutputFolderError, match='walk_frames: an existing '
                       'folder this package did not make'):
        walk_recording(path, str(tmp_path / 'walk.gif'), model, rate_frame,
                       LENGTH, 20, save_frames=True, progress=False)
    assert model.batches == [] and os.listdir(frames) == ['notes.txt']
    os.remove(frames / 'notes.txt')
    walk_recording(path, str(tmp_path / 'walk.gif'), RateModel(), rate_frame,
                   LENGTH, 20, save_frames=True, progress=False)
    many = len(plan_walk(600, LENGTH, 20).centres)
    assert len(_frame_names(frames)) == many
    (frames / 'notes.txt').write_text('mine')
    walk_recording(path, str(tmp_path / 'walk.gif'), RateModel(), rate_frame,
                   LENGTH, 100, save_frames=True, progress=False)
    assert _frame_names(frames) == [
        f'{i:06d}.png' for i in range(len(plan_walk(600, LENGTH, 100)
                                          .centres))] and many > 6
    assert (frames / 'notes.txt').read_text() == 'mine'
    assert not (tmp_path / 'walk.gif.partial').exists()


def test_a_file_the_user_adds_to_the_state_folder_is_kept(tmp_path,
                                                          capsys):
    """An interrupted walk's state folder, with a file the user put in:
    the resumed walk ends as an uninterrupted one and the state folder
    stays with only that file, named on stderr."""
    path, video, partial = _interrupted(tmp_path, 'cut')
    with open(os.path.join(partial, 'notes.txt'), 'w') as f:
        f.write('mine')
    report = _resume(path, video)
    assert report.resumed == 15
    _same_walk(tmp_path / 'whole', tmp_path / 'cut')
    assert os.listdir(partial) == ['notes.txt']
    assert 'partial: kept: it holds files this package did not write' in \
        capsys.readouterr().err


def test_a_walk_to_a_fifo_or_device_is_refused_before_any_work(tmp_path):
    """A walk's CSV and state folder lie beside its video: a FIFO at the
    video's path (a shell's ``>(cat)``) is refused naming it, before the
    model runs, and stays a FIFO."""
    path = _recording(str(tmp_path / 'rec.dat'), 300)
    fifo = tmp_path / 'walk.mp4'
    os.mkfifo(fifo)
    model = RateModel()
    with pytest.raises(OutputFolderError, match='walk.mp4: a fifo'):
        walk_recording(path, str(fifo), model, rate_frame, LENGTH, 20,
                       progress=False)
    assert model.batches == []
    assert sorted(os.listdir(tmp_path)) == ['rec.dat', 'rec.dat.json',
                                            'walk.mp4']
