"""Spike file reading and writing (``wgse_mmseg.fileio.spike_files``)."""
import hashlib
import json
import os
import os.path as osp
import re
import struct
import tempfile

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from wgse_mmseg.argument_checks import ArgumentError
from wgse_mmseg.core import spike_formats
from wgse_mmseg.fileio import atomic, images, spike_arrays, spike_files
from wgse_mmseg.core.spike_formats import SpikeFileError
from wgse_mmseg.fileio.spike_files import load_spikes, save_spikes, spike_shape


def _random_spikes(shape, seed=0, p=0.3):
    return (np.random.default_rng(seed).random(shape) < p).astype(np.uint8)


def _path_in_message(path):
    return re.escape(str(path))


# ------------------------------------------------------------ round trips
@st.composite
def _streams(draw, dat=False):
    steps = draw(st.integers(1, 12))
    if dat:
        height = draw(st.integers(1, 8))
        # height * width must be a multiple of 8 for .dat
        step = 8 // np.gcd(height, 8)
        width = step * draw(st.integers(1, 24 // step + 1))
    else:
        height = draw(st.integers(1, 9))
        width = draw(st.integers(1, 9))
    seed = draw(st.integers(0, 2**32 - 1))
    p = draw(st.sampled_from([0.0, 0.3, 1.0]))
    return _random_spikes((steps, height, width), seed, p)


@given(spikes=_streams(dat=True))
def test_round_trip_dat(spikes):
    steps, height, width = spikes.shape
    with tempfile.TemporaryDirectory() as tmp:
        path = osp.join(tmp, 'a.dat')
        save_spikes(path, spikes)
        assert osp.getsize(path) == steps * height * width // 8
        loaded = load_spikes(path, height=height, width=width)
        assert loaded.dtype == np.uint8
        np.testing.assert_array_equal(loaded, spikes)
        assert spike_shape(path, height, width) == spikes.shape


@pytest.mark.parametrize('ext', ['.spk', '.npy', '.npz'])
@given(spikes=_streams())
def test_round_trip_self_describing(ext, spikes):
    with tempfile.TemporaryDirectory() as tmp:
        path = osp.join(tmp, 'a' + ext)
        save_spikes(path, spikes)
        loaded = load_spikes(path)
        assert loaded.dtype == np.uint8
        assert loaded.flags['C_CONTIGUOUS']
        np.testing.assert_array_equal(loaded, spikes)
        assert tuple(spike_shape(path)) == spikes.shape


def test_spk_size_and_header(tmp_path):
    spikes = _random_spikes((5, 3, 7), seed=1)  # 21 pixels -> 3 bytes
    path = tmp_path / 's.spk'
    save_spikes(str(path), spikes)
    raw = path.read_bytes()
    assert len(raw) == 32 + 5 * 3
    magic, version, steps, height, width = struct.unpack('<8sIIII', raw[:24])
    assert (magic, version, steps, height, width) == (b'WGSESPK1', 1, 5, 3, 7)
    assert raw[24:32] == bytes(8)
    # .spk frames are stored upright, LSB first.
    expected = np.packbits(spikes.reshape(5, -1), axis=1, bitorder='little')
    assert raw[32:] == expected.tobytes()


def test_dat_side_file(tmp_path):
    spikes = _random_spikes((4, 6, 4), seed=2)
    path = str(tmp_path / 'b.dat')
    save_spikes(path, spikes)
    with open(path + '.json', 'w') as f:
        json.dump({'height': 6, 'width': 4}, f)
    np.testing.assert_array_equal(load_spikes(path), spikes)
    assert spike_shape(path) == (4, 6, 4)
    # Arguments that agree with the side file are accepted, others refused.
    assert spike_shape(path, height=6, width=4) == (4, 6, 4)
    with pytest.raises(SpikeFileError, match=r'3x8 given.*b\.dat\.json'
                                             r' says 6x4'):
        spike_shape(path, height=3, width=8)


@pytest.mark.parametrize('ext, record', [
    ('.dat', 'side file'), ('.spk', 'header'), ('.npy', 'array'),
    ('.npz', 'array')])
@pytest.mark.parametrize('height, width', [(10, 4), (10, None), (None, 4)])
def test_a_size_contradicting_the_files_record_is_refused(
        tmp_path, ext, record, height, width):
    """A 4x10 stream read as 10x4 (the same number of bytes) would be
    other frames: every format that records its size refuses a
    caller's size that differs, naming the file and both sizes."""
    spikes = _random_spikes((3, 4, 10), seed=5)
    path = str(tmp_path / ('s' + ext))
    save_spikes(path, spikes)
    if ext == '.dat':
        with open(path + '.json', 'w') as f:
            json.dump({'height': 4, 'width': 10}, f)
    given = f'{height}x{width}'
    for read in (load_spikes, spike_shape):
        with pytest.raises(SpikeFileError) as info:
            read(path, height, width)
        message = str(info.value)
        assert path in message and given in message
        assert record in message and 'says 4x10' in message
    np.testing.assert_array_equal(load_spikes(path, 4, 10), spikes)
    np.testing.assert_array_equal(load_spikes(path, None, 10), spikes)


def test_an_npz_rewritten_with_its_old_mtime_is_read_anew(tmp_path):
    """The window cache keys on what a rewrite always changes: the same
    size, the same inode and the old atime/mtime restored (as ``cp -p``,
    ``rsync -t`` or ``tar`` leave it) still give the new frames."""
    path = str(tmp_path / 'c.npz')
    first = _random_spikes((5, 4, 8), seed=6)
    second = 1 - first
    np.savez(path, spikes=first)
    stat = os.stat(path)
    np.testing.assert_array_equal(load_spikes(path, layout='THW'), first)
    np.savez(tmp_path / 'new.npz', spikes=second)
    data = (tmp_path / 'new.npz').read_bytes()
    assert len(data) == stat.st_size
    with open(path, 'r+b') as f:  # in place: the same inode
        f.write(data)
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    after = os.stat(path)
    assert (after.st_ino, after.st_size, after.st_mtime_ns) == (
        stat.st_ino, stat.st_size, stat.st_mtime_ns)
    np.testing.assert_array_equal(load_spikes(path, layout='THW'), second)


@pytest.mark.parametrize('ext', ['.dat', '.spk', '.npy', '.npz'])
@pytest.mark.parametrize('start, length', [
    (0, None), (0, 1), (3, 4), (5, None), (9, 1), (0, 10), (2, 8)])
def test_windowed_read_equals_slicing(tmp_path, ext, start, length):
    spikes = _random_spikes((10, 4, 6), seed=3)
    path = str(tmp_path / ('w' + ext))
    save_spikes(path, spikes)
    kwargs = dict(height=4, width=6) if ext == '.dat' else {}
    got = load_spikes(path, start=start, length=length, **kwargs)
    stop = 10 if length is None else start + length
    np.testing.assert_array_equal(got, spikes[start:stop])


def test_npz_keys(tmp_path):
    spikes = _random_spikes((3, 2, 2), seed=4)
    single = str(tmp_path / 'single.npz')
    np.savez(single, other=spikes)
    np.testing.assert_array_equal(load_spikes(single, layout='THW'), spikes)
    named = str(tmp_path / 'named.npz')
    np.savez(named, spikes=spikes, extra=np.zeros(3))
    np.testing.assert_array_equal(load_spikes(named, layout='THW'), spikes)
    # Spike-Zoo's recordings (UHSR): spk beside a label; spikes wins
    spike_zoo = str(tmp_path / 'spike_zoo.npz')
    np.savez(spike_zoo, spk=spikes, label=np.array(3),
             label_name=np.array('helicopter'))
    np.testing.assert_array_equal(load_spikes(spike_zoo), spikes)
    both = str(tmp_path / 'both.npz')
    np.savez(both, spk=np.zeros_like(spikes), spikes=spikes)
    np.testing.assert_array_equal(load_spikes(both, layout='THW'), spikes)
    ambiguous = str(tmp_path / 'ambiguous.npz')
    np.savez(ambiguous, a=spikes, b=spikes)
    with pytest.raises(SpikeFileError, match=_path_in_message(ambiguous)):
        load_spikes(ambiguous, layout='THW')


def test_npy_bool_and_int_arrays_accepted(tmp_path):
    spikes = _random_spikes((3, 2, 4), seed=5)
    for dtype in (bool, np.int64, np.float32):
        path = str(tmp_path / f'x_{np.dtype(dtype).name}.npy')
        np.save(path, spikes.astype(dtype))
        got = load_spikes(path, layout='THW')
        assert got.dtype == np.uint8
        np.testing.assert_array_equal(got, spikes)


# ------------------------------------------------------ .dat bit layout
# Hand-computed: the stored frame is the upright frame flipped vertically,
# so upright (row r, col c) is stored at row H-1-r; pixel k = row*W + col of
# the stored frame is bit k%8 of byte k//8 of its frame; frame t starts at
# byte t*H*W/8.
@pytest.mark.parametrize('shape, t, r, c, byte_index, byte_value', [
    # H=4, W=6 (3 bytes per frame); stored row 3, k=3*6+3=21 -> byte 2 of
    # frame 2 (offset 6), bit 5.
    ((3, 4, 6), 2, 0, 3, 6 + 2, 1 << 5),
    # stored row 0, k=0 -> byte 0, bit 0.
    ((3, 4, 6), 0, 3, 0, 0, 1 << 0),
    # stored row 1, k=1*6+5=11 -> byte 1 of frame 1 (offset 3), bit 3.
    ((3, 4, 6), 1, 2, 5, 3 + 1, 1 << 3),
    # H=2, W=8: stored row 1, k=8+7=15 -> byte 1, bit 7.
    ((1, 2, 8), 0, 0, 7, 1, 1 << 7),
    # H=2, W=8: stored row 0, k=2 -> byte 0, bit 2.
    ((1, 2, 8), 0, 1, 2, 0, 1 << 2),
])
def test_dat_bit_layout(tmp_path, shape, t, r, c, byte_index, byte_value):
    spikes = np.zeros(shape, np.uint8)
    spikes[t, r, c] = 1
    path = str(tmp_path / 'one.dat')
    save_spikes(path, spikes)
    expected = bytearray(shape[0] * shape[1] * shape[2] // 8)
    expected[byte_index] = byte_value
    with open(path, 'rb') as f:
        assert f.read() == bytes(expected)
    # And the reader maps the hand-written bytes back to (t, r, c).
    raw_path = str(tmp_path / 'hand.dat')
    with open(raw_path, 'wb') as f:
        f.write(bytes(expected))
    loaded = load_spikes(raw_path, height=shape[1], width=shape[2])
    assert list(zip(*np.nonzero(loaded))) == [(t, r, c)]


# ----------------------------------------------------------------- errors
def _write_dat(tmp_path, name='d.dat', shape=(3, 4, 6)):
    path = str(tmp_path / name)
    save_spikes(path, _random_spikes(shape, seed=6))
    return path


def test_truncated_dat(tmp_path):
    path = _write_dat(tmp_path)  # 3 frames x 3 bytes
    with open(path, 'r+b') as f:
        f.truncate(8)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path, height=4, width=6)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        spike_shape(path, height=4, width=6)


def test_empty_dat(tmp_path):
    path = str(tmp_path / 'empty.dat')
    open(path, 'wb').close()
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path, height=4, width=6)


def test_dat_frame_not_whole_bytes(tmp_path):
    path = _write_dat(tmp_path)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path, height=3, width=3)


def test_dat_without_geometry(tmp_path):
    path = _write_dat(tmp_path)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path, height=4)


def test_spk_truncated(tmp_path):
    path = str(tmp_path / 't.spk')
    save_spikes(path, _random_spikes((4, 3, 5), seed=7))
    with open(path, 'r+b') as f:
        f.truncate(osp.getsize(path) - 1)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)
    with open(path, 'r+b') as f:
        f.truncate(20)  # shorter than the 32-byte header
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)


def test_spk_bad_magic(tmp_path):
    path = str(tmp_path / 'm.spk')
    save_spikes(path, _random_spikes((4, 3, 5), seed=8))
    with open(path, 'r+b') as f:
        f.write(b'NOTSPIKE')
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)


def test_spk_bad_version(tmp_path):
    path = str(tmp_path / 'v.spk')
    save_spikes(path, _random_spikes((4, 3, 5), seed=8))
    with open(path, 'r+b') as f:
        f.seek(8)
        f.write(struct.pack('<I', 2))
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)


@pytest.mark.parametrize('ext', ['.dat', '.spk', '.npy', '.npz'])
@pytest.mark.parametrize('start, length', [
    (8, 5), (10, None), (10, 1), (0, 11)])
def test_window_past_end(tmp_path, ext, start, length):
    path = str(tmp_path / ('e' + ext))
    save_spikes(path, _random_spikes((10, 4, 6), seed=9))
    kwargs = dict(height=4, width=6) if ext == '.dat' else {}
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path, start=start, length=length, **kwargs)


@pytest.mark.parametrize('start, length, match', [
    (-1, 2, 'load_spikes: start must be an integer >= 0'),
    (1.5, 2, 'load_spikes: start must be an integer >= 0'),
    (0, 0, 'load_spikes: length must be an integer >= 1'),
    (0, 2.0, 'load_spikes: length must be an integer >= 1')])
def test_window_arguments_are_named(tmp_path, start, length, match):
    path = str(tmp_path / 'e.npy')
    save_spikes(path, _random_spikes((10, 4, 6), seed=9))
    with pytest.raises(ValueError, match=match):
        load_spikes(path, start=start, length=length)


def test_npy_values_outside_binary(tmp_path):
    path = str(tmp_path / 'two.npy')
    spikes = _random_spikes((3, 2, 4), seed=10)
    spikes[1, 1, 1] = 2
    np.save(path, spikes)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)
    neg = str(tmp_path / 'neg.npz')
    np.savez(neg, spikes=-spikes.astype(np.int8))
    with pytest.raises(SpikeFileError, match=_path_in_message(neg)):
        load_spikes(neg)


@pytest.mark.parametrize('shape', [(4, 6), (2, 3, 4, 5), (7, )])
def test_npy_wrong_ndim(tmp_path, shape):
    path = str(tmp_path / 'nd.npy')
    np.save(path, np.zeros(shape, np.uint8))
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)


def test_npy_not_an_array(tmp_path):
    path = str(tmp_path / 'junk.npy')
    with open(path, 'wb') as f:
        f.write(b'this is not a numpy file')
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)


def test_unknown_extension(tmp_path):
    path = str(tmp_path / 'x.txt')
    with open(path, 'wb') as f:
        f.write(bytes(24))
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path, height=4, width=6)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        save_spikes(path, np.zeros((1, 4, 6), np.uint8))


def test_missing_file(tmp_path):
    path = str(tmp_path / 'missing.spk')
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)


# ------------------------------------------------------- atomic writes
def _listing(directory):
    return sorted(os.listdir(directory))


@pytest.mark.parametrize('ext', ['.dat', '.spk', '.npy', '.npz'])
@pytest.mark.parametrize('bad', ['value_2', 'negative', 'ndim', 'empty'])
def test_failed_save_leaves_nothing(tmp_path, ext, bad):
    spikes = _random_spikes((2, 4, 6), seed=11).astype(np.int16)
    if bad == 'value_2':
        spikes[0, 0, 0] = 2
    elif bad == 'negative':
        spikes[0, 0, 0] = -1
    elif bad == 'ndim':
        spikes = spikes[0]
    else:
        spikes = spikes[:0]
    path = str(tmp_path / ('bad' + ext))
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        save_spikes(path, spikes)
    assert _listing(tmp_path) == []


def test_dat_save_requires_whole_bytes(tmp_path):
    path = str(tmp_path / 'odd.dat')
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        save_spikes(path, np.zeros((2, 3, 3), np.uint8))
    assert _listing(tmp_path) == []


@pytest.mark.parametrize('ext', ['.dat', '.spk'])
def test_failure_mid_write_keeps_old_file_and_no_temp(tmp_path, monkeypatch,
                                                      ext):
    path = str(tmp_path / ('keep' + ext))
    old = _random_spikes((2, 4, 6), seed=12)
    save_spikes(path, old)
    before = open(path, 'rb').read()

    def broken_pack(spikes):
        raise RuntimeError('disk full (simulated)')

    monkeypatch.setattr(spike_formats, 'pack_frames', broken_pack)
    with pytest.raises(RuntimeError, match='simulated'):
        save_spikes(path, _random_spikes((2, 4, 6), seed=13))
    assert _listing(tmp_path) == [osp.basename(path)]
    assert open(path, 'rb').read() == before


@pytest.mark.parametrize('umask', [0o022, 0o077, 0o002])
def test_atomic_writes_leave_the_process_umask_alone(tmp_path, monkeypatch,
                                                     umask):
    """A written file gets the mode ``open`` gives under the umask, and
    the umask is never changed, not even for a moment (``os.umask`` sets
    the process-wide mask: a file another thread made meanwhile would be
    world-writable)."""
    import threading
    set_umask = os.umask
    previous = set_umask(umask)
    try:
        with open(tmp_path / 'reference', 'w'):
            pass
        changes = []
        monkeypatch.setattr(os, 'umask', lambda mask: changes.append(mask)
                            or umask)
        made = []

        def other_thread():  # files made while the writes run
            for index in range(200):
                path = tmp_path / f'other{index}'
                with open(path, 'w'):
                    pass
                made.append(path)
        thread = threading.Thread(target=other_thread)
        thread.start()
        for index in range(50):
            atomic.write_bytes(str(tmp_path / f'written{index}.bin'), b'x')
        save_spikes(str(tmp_path / 'spikes.npy'),
                    _random_spikes((2, 3, 3), seed=15))
        thread.join()
    finally:
        set_umask(previous)
    assert changes == []
    expected = os.stat(tmp_path / 'reference').st_mode & 0o777
    assert expected == 0o666 & ~umask
    for path in [tmp_path / f'written{i}.bin' for i in range(50)] + [
            tmp_path / 'spikes.npy', tmp_path / 'spikes.npy.json'] + made:
        assert os.stat(path).st_mode & 0o777 == expected, path


def test_save_creates_directories(tmp_path):
    path = str(tmp_path / 'a' / 'b' / 'c.spk')
    spikes = _random_spikes((2, 3, 3), seed=14)
    save_spikes(path, spikes)
    np.testing.assert_array_equal(load_spikes(path), spikes)
    assert _listing(tmp_path / 'a' / 'b') == ['c.spk']


# ------------------------------------------------------ shared REDS sample
SAMPLE_DAT = ('data', 'reds_sample', 'spike', '203_part2_key_id151.dat')
SAMPLE_GT = ('data', 'reds_sample', 'gt', '203_part2_key_id151.png')


@pytest.fixture(scope='module')
def reds_sample(request):
    shared_dir = request.getfixturevalue('shared_dir')
    dat = osp.join(shared_dir, *SAMPLE_DAT)
    gt = osp.join(shared_dir, *SAMPLE_GT)
    if not (osp.exists(dat) and osp.exists(gt)):
        pytest.skip(f'REDS sample not found under {shared_dir}')
    return dat, gt


def _corr(a, b):
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


def test_reds_sample_reads_upright(reds_sample):
    import cv2
    dat, gt_path = reds_sample
    assert spike_shape(dat, 250, 400) == (301, 250, 400)
    window = load_spikes(dat, height=250, width=400, start=130, length=41)
    assert window.shape == (41, 250, 400)
    assert set(np.unique(window)) <= {0, 1}
    image = np.clip(window.mean(axis=0) / 0.6, 0, 1)
    gt = cv2.imread(gt_path, cv2.IMREAD_GRAYSCALE)
    assert gt is not None and gt.shape == (250, 400)
    gt = gt.astype(np.float64) / 255
    assert _corr(image, gt) > 0.9
    assert _corr(image[::-1], gt) < 0.5


def test_reds_sample_rewrite_is_byte_identical(reds_sample, tmp_path):
    dat, _ = reds_sample
    spikes = load_spikes(dat, height=250, width=400)
    assert spikes.shape == (301, 250, 400)
    out = str(tmp_path / 'copy.dat')
    save_spikes(out, spikes)
    with open(dat, 'rb') as f1, open(out, 'rb') as f2:
        assert f1.read() == f2.read()


# Non-binary values inside [0, 1] and NaN once passed a range-only check and
# were truncated to 0; a malformed side file once raised a bare KeyError.


@pytest.mark.parametrize('value', [0.5, np.nan], ids=['half', 'nan'])
@pytest.mark.parametrize('ext', ['.dat', '.npy'])
def test_save_rejects_non_binary_values_in_range(tmp_path, ext, value):
    spikes = np.zeros((1, 2, 4))
    spikes[0, 0, 0] = value
    path = str(tmp_path / ('frac' + ext))
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        save_spikes(path, spikes)
    assert _listing(tmp_path) == []


@pytest.mark.parametrize('value', [0.5, np.nan], ids=['half', 'nan'])
def test_load_rejects_non_binary_values_in_range(tmp_path, value):
    spikes = np.zeros((1, 2, 4))
    spikes[0, 0, 0] = value
    path = str(tmp_path / 'frac.npy')
    np.save(path, spikes)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)


@pytest.mark.parametrize('content', ['{"h": 4, "w": 6}', '{bad json'],
                         ids=['missing-keys', 'invalid-json'])
def test_bad_side_file(tmp_path, content):
    path = _write_dat(tmp_path)
    with open(path + '.json', 'w') as f:
        f.write(content)
    with pytest.raises(SpikeFileError, match=_path_in_message(path)):
        load_spikes(path)


def test_write_png_round_trip_and_nothing_on_failure(tmp_path):
    import cv2
    label = np.random.default_rng(2).integers(0, 19, (7, 9), dtype=np.uint8)
    bgr = np.random.default_rng(3).integers(0, 256, (5, 4, 3),
                                            dtype=np.uint8)
    for name, image in (('label.png', label), ('colour.png', bgr)):
        path = str(tmp_path / 'out' / name)
        images.write_png(path, image)
        np.testing.assert_array_equal(
            cv2.imread(path, cv2.IMREAD_UNCHANGED), image)
    with pytest.raises((OSError, cv2.error)):  # nothing to encode
        images.write_png(str(tmp_path / 'empty.png'),
                         np.zeros((0, 3), np.uint8))
    assert sorted(os.listdir(tmp_path)) == ['out']  # no file, no temp file


# ---------------------------------------------------------------- fuzzing
@st.composite
def _damaged_files(draw):
    """A valid spike file's bytes, then truncated, overwritten in places or
    replaced by random bytes."""
    ext = draw(st.sampled_from(['.dat', '.spk', '.npy', '.npz']))
    spikes = _random_spikes((draw(st.integers(1, 6)), 4, 6),
                            draw(st.integers(0, 2**16)))
    with tempfile.TemporaryDirectory() as tmp:
        path = osp.join(tmp, f'clip{ext}')
        save_spikes(path, spikes)
        with open(path, 'rb') as f:
            data = bytearray(f.read())
    damage = draw(st.sampled_from(['truncate', 'overwrite', 'random']))
    if damage == 'truncate':
        data = data[:draw(st.integers(0, max(len(data) - 1, 0)))]
    elif damage == 'overwrite':
        for _ in range(draw(st.integers(1, 8))):
            index = draw(st.integers(0, len(data) - 1))
            data[index] = draw(st.integers(0, 255))
    else:
        data = bytearray(draw(st.binary(max_size=400)))
    return ext, bytes(data)


@given(_damaged_files())
@example(('.npz', b'PK\x03\x04'))  # a zip's magic and nothing else
@example(('.npy', b'\x93NUMPY\x01\x00'))
@example(('.npy', b"\x93NUMPY\x01\x00v\x00{'descr': '|u1'{ 'fortran_order': "
                  b"False, 'shape': (1, 4, 6), }" + b' ' * 55 + b'\n' +
          bytes(24)))  # a header NumPy's tokenizer cannot parse
def test_damaged_files_read_correctly_or_fail_naming_the_file(damaged):
    """Random bytes and truncations of valid files: a stream of 0/1 uint8
    frames of the stated shape, or a SpikeFileError naming the file; never
    another exception."""
    ext, data = damaged
    with tempfile.TemporaryDirectory() as tmp:
        path = osp.join(tmp, f'clip{ext}')
        with open(path, 'wb') as f:
            f.write(data)
        if ext in ('.dat', '.npy'):  # their side files
            with open(path + '.json', 'w') as f:
                json.dump(dict(height=4, width=6) if ext == '.dat' else
                          dict(layout='THW'), f)
        try:
            shape = spike_shape(path)
            spikes = load_spikes(path)
        except SpikeFileError as error:
            assert path in str(error)
            return
        assert spikes.dtype == np.uint8 and spikes.shape == shape
        assert spikes.ndim == 3 and spikes.size > 0
        assert set(np.unique(spikes)) <= {0, 1}


# ------------------------------------------------- hostile sizes and values
def _write_npz_bomb(path, shape, frames_written=None, fortran=False):
    """An ``.npz`` whose ``spikes.npy`` member declares a ``uint8`` array
    of ``shape`` and holds zeros: each MiB of zeros deflates to ~1 kB, so a
    GiB takes ~1 MB on disk. The member is built from one compressed piece
    (a frame, at most a MiB) repeated (each piece ends with a full flush, so
    pieces are independent), not by compressing a GiB. ``frames_written``
    (default ``shape[0]``) frames of data follow the header; the zip declares
    the size the header says, so fewer or more frames make a member that lies.
    ``fortran``: the header says Fortran order (the zeros are the same)."""
    import io
    import struct
    import zlib
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, dict(descr='|u1', fortran_order=fortran, shape=shape))
    header = header.getvalue()
    frame = shape[1] * shape[2]
    steps = shape[0] if frames_written is None else frames_written
    piece = bytes(min(frame, 1 << 20))
    assert frame % len(piece) == 0

    def deflated(data):
        compressor = zlib.compressobj(9, zlib.DEFLATED, -15)
        return compressor.compress(data) + compressor.flush(zlib.Z_FULL_FLUSH)

    pieces = steps * frame // len(piece)
    data = deflated(header) + deflated(piece) * pieces + zlib.compressobj(
        9, zlib.DEFLATED, -15).flush()
    crc = zlib.crc32(header)
    for _ in range(pieces):
        crc = zlib.crc32(piece, crc)
    size = len(header) + shape[0] * frame  # what the zip declares
    name = b'spikes.npy'
    local = struct.pack('<4sHHHHHIIIHH', b'PK\x03\x04', 20, 0, 8, 0, 0x21,
                        crc, len(data), size, len(name), 0) + name
    central = struct.pack('<4sHHHHHHIIIHHHHHII', b'PK\x01\x02', 20, 20, 0,
                          8, 0, 0x21, crc, len(data), size, len(name), 0, 0,
                          0, 0, 0, 0) + name
    end = struct.pack('<4sHHHHIIH', b'PK\x05\x06', 0, 0, 1, 1, len(central),
                      len(local) + len(data), 0)
    with open(path, 'wb') as f:
        f.write(local + data + central + end)


@pytest.fixture
def inflated(monkeypatch):
    """Counts the bytes zip members inflate (ZipExtFile.read, which its
    seek also uses)."""
    import zipfile
    counted = [0]
    read = zipfile.ZipExtFile.read

    def counting(self, n=-1):
        data = read(self, n)
        counted[0] += len(data)
        return data

    monkeypatch.setattr(zipfile.ZipExtFile, 'read', counting)
    return counted


def test_npz_bomb_is_read_lazily_within_bounds(tmp_path):
    """1 MB on disk, 1 GiB inflated: three reads of a 9-frame window stay
    far from inflating it (< 5 s, < 100 MB extra)."""
    import time
    import tracemalloc
    path = str(tmp_path / 'bomb.npz')
    _write_npz_bomb(path, (1024, 1024, 1024))
    assert osp.getsize(path) < 2e6
    tracemalloc.start()
    began = time.perf_counter()
    for _ in range(3):
        assert spike_shape(path, layout='THW') == (1024, 1024, 1024)
        window = load_spikes(path, start=0, length=9, layout='THW')
        assert window.shape == (9, 1024, 1024) and not window.any()
    seconds = time.perf_counter() - began
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert seconds < 5 and peak < 100e6, (seconds, peak)


def test_npz_member_inflates_once_up_to_the_window(tmp_path, inflated):
    path = str(tmp_path / 'clip.npz')
    _write_npz_bomb(path, (64, 256, 256))  # 4 MiB inflated
    frame = 256 * 256
    window = load_spikes(path, start=30, length=9, layout='THW')
    assert window.shape == (9, 256, 256) and not window.any()
    first = inflated[0]
    assert 39 * frame <= first <= 39 * frame + 1024  # the npy header
    load_spikes(path, start=30, length=9, layout='THW')
    load_spikes(path, start=30, length=9, layout='THW')
    assert inflated[0] - first < 1024  # the headers of spike_shape only
    # a rewritten file is read anew, not served from the last read
    spikes = _random_spikes((64, 4, 6), seed=1)
    save_spikes(path, spikes)
    np.testing.assert_array_equal(load_spikes(path, start=30, length=9),
                                  spikes[30:39])


def test_npz_member_over_the_limit_is_refused_before_inflating(
        tmp_path, inflated, monkeypatch):
    path = str(tmp_path / 'bomb.npz')
    _write_npz_bomb(path, (64, 256, 256))
    for module in (spike_arrays, spike_formats):
        monkeypatch.setattr(module, 'READ_LIMIT_BYTES', 1 << 20)
    for read in (spike_shape, load_spikes):
        with pytest.raises(SpikeFileError,
                           match=_path_in_message(path) + '.*declares '
                           f'{64 * 256 * 256 + 128} inflated bytes'):
            read(path)
    assert inflated[0] == 0


@pytest.mark.parametrize('frames_written', [8, 64])
def test_npz_member_inflating_past_its_declared_size_is_stopped(
        tmp_path, inflated, frames_written):
    """A member holding 64 frames of data but declaring 1 (or declaring 64
    and holding 8): it inflates no more than it declared, and a read that
    meets the lie fails naming the file."""
    path = str(tmp_path / 'liar.npz')
    shape = (16 if frames_written == 64 else 64, 256, 256)
    _write_npz_bomb(path, shape, frames_written)
    declared = 128 + shape[0] * 256 * 256
    try:
        spikes = load_spikes(path, layout='THW')
    except SpikeFileError as error:
        assert path in str(error)
    else:  # cannot happen: the CRC or the length disagrees at the end
        pytest.fail(f'read {spikes.shape} from a lying member')
    assert inflated[0] <= declared


def test_npy_header_declaring_more_than_the_file_is_refused(tmp_path):
    import io
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, dict(descr='<f8', fortran_order=False,
                     shape=(10**6, 10**6, 10**6)))
    path = str(tmp_path / 'huge.npy')
    with open(path, 'wb') as f:
        f.write(header.getvalue() + bytes(64))
    for read in (spike_shape, load_spikes):
        with pytest.raises(SpikeFileError,
                           match=_path_in_message(path) + '.*header says'):
            read(path, layout='THW')


def test_spk_header_with_an_empty_dimension_is_refused(tmp_path):
    path = str(tmp_path / 'flat.spk')
    with open(path, 'wb') as f:
        f.write(struct.pack('<8sIIII8x', b'WGSESPK1', 1, 5, 0, 8))
    with pytest.raises(SpikeFileError, match='each must be >= 1'):
        load_spikes(path)


@pytest.mark.parametrize('ext', ['.dat', '.spk', '.npy'])  # .npz: above
def test_windows_over_the_read_limit_are_refused(tmp_path, ext, monkeypatch):
    path = str(tmp_path / ('clip' + ext))
    spikes = _random_spikes((10, 4, 6), seed=3)
    save_spikes(path, spikes)
    kwargs = dict(height=4, width=6) if ext == '.dat' else {}
    for module in (spike_arrays, spike_formats):
        monkeypatch.setattr(module, 'READ_LIMIT_BYTES', 4 * 24)
    np.testing.assert_array_equal(
        load_spikes(path, start=6, length=4, **kwargs), spikes[6:])
    with pytest.raises(SpikeFileError, match='read limit'):
        load_spikes(path, start=5, length=5, **kwargs)


@pytest.mark.parametrize('name, value', [
    ('start', 1.5), ('start', -1), ('start', True), ('start', '0'),
    ('start', None), ('length', 0), ('length', 2.5), ('length', '2'),
    ('height', 4.0), ('width', 0), ('width', 'x' * 10000)])
@pytest.mark.parametrize('ext', ['.dat', '.npz'])
def test_bad_read_arguments_are_named(tmp_path, name, value, ext):
    path = str(tmp_path / ('clip' + ext))
    save_spikes(path, _random_spikes((4, 4, 6), seed=4))
    kwargs = dict(height=4, width=6, start=1, length=2)
    kwargs[name] = value
    with pytest.raises(ArgumentError,
                       match=f'load_spikes: {name} must be an integer') \
            as info:
        load_spikes(path, **kwargs)
    assert len(str(info.value)) < 600


@pytest.mark.parametrize('content, match', [
    ('{"height": "4", "width": 6}', 'an integer >= 1'),
    ('{"height": 4.0, "width": 6}', 'an integer >= 1'),
    ('{"height": Infinity, "width": 6}', 'an integer >= 1'),
    ('{"height": true, "width": 6}', 'an integer >= 1'),
    ('[4, 6]', 'an integer >= 1'),
    ('[' * 100000 + ']' * 100000, 'nested too deeply'),
    ('{"height": 4, "width": 6, "pad": "' + 'x' * (1 << 20) + '"}',
     'larger than'),
    (b'\xff\xfe', 'UTF-8'),
])
def test_hostile_side_files(tmp_path, content, match):
    path = _write_dat(tmp_path)
    with open(path + '.json', 'wb') as f:
        f.write(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(SpikeFileError, match=match) as info:
        load_spikes(path)
    assert path in str(info.value) and len(str(info.value)) < 600


@st.composite
def _arrays(draw):
    """A 0/1 ``(T, H, W)`` array of some dtype, in C or Fortran order."""
    shape = (draw(st.integers(1, 8)), draw(st.integers(1, 5)),
             draw(st.integers(1, 5)))
    dtype = draw(st.sampled_from(['bool', 'uint8', '>i2', 'float32']))
    array = _random_spikes(shape, draw(st.integers(0, 2**16))).astype(dtype)
    return np.asfortranarray(array) if draw(st.booleans()) else array


@pytest.mark.parametrize('ext', ['.npy', '.npz'])
@given(array=_arrays(), start=st.integers(0, 9),
       length=st.one_of(st.none(), st.integers(1, 9)),
       layout=st.sampled_from(['THW', 'HWT']))
def test_array_windows_equal_slicing(ext, array, start, length, layout):
    """Any dtype and memory order NumPy writes, stored ``(T, H, W)`` or
    ``(H, W, T)``: with its layout given, the window is the slice of the
    ``(T, H, W)`` clip, as uint8, or the window does not fit and the error
    names the file."""
    stored = array if layout == 'THW' else np.moveaxis(array, 0, -1)
    with tempfile.TemporaryDirectory() as tmp:
        path = osp.join(tmp, 'a' + ext)
        (np.save if ext == '.npy' else np.savez)(path, stored)
        stop = len(array) if length is None else start + length
        if start >= len(array) or stop > len(array):
            with pytest.raises(SpikeFileError, match=_path_in_message(path)):
                load_spikes(path, start=start, length=length, layout=layout)
            return
        assert spike_shape(path, layout=layout) == array.shape
        window = load_spikes(path, start=start, length=length, layout=layout)
        assert window.dtype == np.uint8
        np.testing.assert_array_equal(window, array[start:stop])


_ANY_VALUE = st.one_of(
    st.none(), st.booleans(), st.integers(-2**70, 2**70),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=20),
    st.lists(st.integers(), max_size=3))


@pytest.mark.parametrize('ext', ['.dat', '.spk', '.npz'])
@given(start=_ANY_VALUE, length=_ANY_VALUE)
def test_any_window_arguments_read_or_name_the_problem(ext, start, length):
    with tempfile.TemporaryDirectory() as tmp:
        path = osp.join(tmp, 'a' + ext)
        spikes = _random_spikes((6, 4, 6), seed=5)
        save_spikes(path, spikes)
        kwargs = dict(height=4, width=6) if ext == '.dat' else {}
        try:
            window = load_spikes(path, start=start, length=length, **kwargs)
        except SpikeFileError as error:
            assert path in str(error)
            return
        except ArgumentError as error:
            assert error.argument in ('start', 'length')
            return
        np.testing.assert_array_equal(
            window, spikes[start:None if length is None else start + length])


# ------------------------------------------------------ the format registry
def test_the_registry_is_the_one_list_of_formats():
    from wgse_bench import simulator
    formats = spike_files.SPIKE_FORMATS
    assert spike_files.SPIKE_EXTENSIONS == tuple(formats) == (
        '.dat', '.spk', '.npy', '.npz')
    for ext, fmt in spike_files.SPIKE_FORMATS.items():
        assert fmt.extension == ext == ext.lower()
    assert simulator.SPIKE_EXTENSIONS is spike_files.SPIKE_EXTENSIONS


@pytest.mark.parametrize('ext', sorted(spike_files.SPIKE_FORMATS))
def test_every_registered_format_round_trips_a_window(tmp_path, ext):
    """What a new entry must do, on the shape .dat needs (8 | H*W)."""
    spikes = _random_spikes((7, 4, 6), seed=11)
    path = str(tmp_path / ('clip' + ext.upper()))  # any case
    written = save_spikes(path, spikes)
    assert written.size == osp.getsize(path)
    with open(path, 'rb') as f:
        assert hashlib.sha256(f.read()).hexdigest() == \
            written.sha256
    size = dict(height=4, width=6)
    assert spike_shape(path, **size) == (7, 4, 6)
    got = load_spikes(path, start=2, length=3, **size)
    assert got.dtype == np.uint8
    np.testing.assert_array_equal(got, spikes[2:5])


def test_one_entry_adds_a_format(tmp_path, monkeypatch):
    """A format is one entry: layout, shape, read and encode of an
    (illustrative) raw byte-per-spike format with a 3-int header; the public
    functions dispatch to it and keep their own checks."""
    header = struct.Struct('<3I')

    def layout(path, layout):
        return 'THW'

    def shape(path, height, width, layout):
        with open(path, 'rb') as f:
            return header.unpack(f.read(header.size))

    def read(path, shape, start, length, layout):
        start, length = spike_formats.check_window(
            path, shape[0], start, length, shape[1] * shape[2])
        data = np.fromfile(path, np.uint8, offset=header.size)
        return data.reshape(shape)[start:start + length]

    def encode(path, spikes):
        return header.pack(*spikes.shape) + spikes.tobytes()

    fmt = spike_files.SpikeFormat('.raw', layout, shape, read, encode)
    monkeypatch.setitem(spike_files.SPIKE_FORMATS, '.raw', fmt)
    spikes = _random_spikes((5, 3, 2), seed=12)
    path = str(tmp_path / 'clip.raw')
    save_spikes(path, spikes)
    assert spike_shape(path) == (5, 3, 2)
    np.testing.assert_array_equal(load_spikes(path, start=1), spikes[1:])
    with pytest.raises(SpikeFileError, match='only 0 and 1'):
        save_spikes(path, spikes * 2)
    with pytest.raises(SpikeFileError, match=r'frames \[4, 6\)'):
        load_spikes(path, start=4, length=2)


def test_a_temporary_is_named_after_its_target(tmp_path):
    """A killed writer's temporary file is found for its target only, so a
    run removes its own and leaves another process's beside it."""
    target = tmp_path / 'a_spike.spk'
    with atomic.atomic_output(str(target)) as f:
        f.write(b'x')
        (left, ) = [p for p in os.listdir(tmp_path) if p.startswith('.tmp-')]
        assert left.startswith('.tmp-a_spike.spk.') and left.endswith('.spk')
        assert atomic.temporaries_of([str(target)]) == [
            str(tmp_path / left)]
        assert atomic.temporaries_of([str(tmp_path / 'a_spike')]) == []
        assert atomic.temporaries_of([str(tmp_path / 'spike.spk')]) == []
        assert atomic.temporaries_of([str(tmp_path / 'no' / 'x')]) == []
    assert os.listdir(tmp_path) == ['a_spike.spk']
    assert atomic.temporaries_of([str(target)]) == []


# ------------------------------------------------------------ layouts
@pytest.mark.parametrize('ext', ['.npy', '.npz'])
@pytest.mark.parametrize('order', ['C', 'F'])
def test_the_same_clip_written_both_ways_reads_the_same(tmp_path, ext,
                                                        order):
    """A clip stored (T, H, W) and (H, W, T) (as another tool writes it,
    in either memory order) reads as the same (T, H, W) clip, whole and
    in windows, given each file's layout."""
    clip = _random_spikes((11, 5, 7), seed=21)
    paths = {}
    for layout, stored in (('THW', clip), ('HWT', clip.transpose(1, 2, 0))):
        paths[layout] = str(tmp_path / f'{layout}{ext}')
        stored = np.asarray(stored, order=order)
        if ext == '.npy':
            np.save(paths[layout], stored)
        else:
            np.savez(paths[layout], spikes=stored)
    for layout, path in paths.items():
        assert spike_shape(path, layout=layout) == (11, 5, 7)
        np.testing.assert_array_equal(load_spikes(path, layout=layout), clip)
        for start, length in ((0, 1), (3, 5), (10, 1), (4, None)):
            np.testing.assert_array_equal(
                load_spikes(path, start=start, length=length, layout=layout),
                clip[start:None if length is None else start + length])
    with pytest.raises(SpikeFileError, match=r'frames \[9, 12\)'):
        load_spikes(paths['HWT'], start=9, length=3, layout='HWT')


@pytest.mark.parametrize('ext', ['.npy', '.npz'])
def test_an_array_that_does_not_record_its_layout_asks_for_it(tmp_path,
                                                              ext):
    path = str(tmp_path / ('clip' + ext))
    array = _random_spikes((6, 4, 5), seed=22)
    (np.save if ext == '.npy' else np.savez)(path, array)
    for read in (spike_shape, load_spikes):
        with pytest.raises(SpikeFileError) as error:
            read(path)
        message = str(error.value)
        for part in (path, '6x4x5', 'does not record its layout',
                     '6 frames of 4x5 (layout THW)',
                     '5 frames of 6x4 (layout HWT)', "layout='THW'",
                     '--layout THW', f'{path}.json',
                     '{"layout": "THW"}'):
            assert part in message, part
    # what the message says to add works: the argument, or the side file
    np.testing.assert_array_equal(load_spikes(path, layout='THW'), array)
    with open(path + '.json', 'w') as f:
        json.dump({'layout': 'THW'}, f)
    np.testing.assert_array_equal(load_spikes(path), array)


@pytest.mark.parametrize('ext', ['.npy', '.npz'])
def test_save_spikes_records_the_layout(tmp_path, ext):
    """.npz: a member "layout" (NumPy's own reader still reads "spikes");
    .npy: the side file; then no layout is needed, and another is an error
    naming the record."""
    clip = _random_spikes((6, 4, 5), seed=23)
    path = str(tmp_path / ('clip' + ext))
    save_spikes(path, clip)
    if ext == '.npz':
        with np.load(path) as archive:
            assert archive['layout'] == 'THW'
            np.testing.assert_array_equal(archive['spikes'], clip)
        where = 'its member "layout"'
    else:
        np.testing.assert_array_equal(np.load(path), clip)
        with open(path + '.json') as f:
            assert json.load(f) == {'layout': 'THW'}
        where = f'its side file {path}.json'
    np.testing.assert_array_equal(load_spikes(path), clip)
    np.testing.assert_array_equal(load_spikes(path, layout='THW'), clip)
    with pytest.raises(SpikeFileError,
                       match=re.escape(f'{path}: {where} records layout THW,'
                                       f' but layout HWT was given')):
        load_spikes(path, layout='HWT')


def test_a_recorded_hwt_layout_is_read_without_an_argument(tmp_path):
    clip = _random_spikes((6, 4, 5), seed=24)
    member = str(tmp_path / 'member.npz')
    np.savez(member, spikes=clip.transpose(1, 2, 0), layout='HWT')
    side = str(tmp_path / 'side.npy')
    np.save(side, clip.transpose(1, 2, 0))
    with open(side + '.json', 'w') as f:
        json.dump({'layout': 'HWT'}, f)
    for path in (member, side):
        assert spike_shape(path) == (6, 4, 5)
        np.testing.assert_array_equal(load_spikes(path, start=2, length=3),
                                      clip[2:5])
        with pytest.raises(SpikeFileError, match='records layout HWT'):
            load_spikes(path, layout='THW')


def test_the_spike_zoo_key_states_its_layout(tmp_path):
    """Spike-Zoo's .npz convention (UHSR): key "spk", (T, H, W), beside
    its label members."""
    clip = _random_spikes((8, 5, 5), seed=25)
    path = str(tmp_path / 'uhsr.npz')
    np.savez(path, spk=clip, label=np.array(3), label_name=np.array('heli'))
    assert spike_shape(path) == (8, 5, 5)
    np.testing.assert_array_equal(load_spikes(path, start=1, length=4),
                                  clip[1:5])
    np.testing.assert_array_equal(load_spikes(path, layout='THW'), clip)
    with pytest.raises(SpikeFileError, match='key "spk".*records layout '
                       'THW, but layout HWT'):
        load_spikes(path, layout='HWT')


def test_the_real_uhsr_recording_reads_as_published(shared_dir):
    path = osp.join(shared_dir, 'data', 'real', 'uhsr_helicopter.npz')
    if not osp.exists(path):
        pytest.skip(f'{path} is not here')
    assert spike_shape(path) == (200, 250, 250)
    with np.load(path) as archive:
        expected = archive['spk'][40:81]
    np.testing.assert_array_equal(load_spikes(path, start=40, length=41),
                                  expected)


def test_records_that_disagree_or_hold_no_layout_are_errors(tmp_path):
    clip = _random_spikes((4, 2, 3), seed=26)
    both = str(tmp_path / 'both.npz')
    np.savez(both, spikes=clip, layout='THW')
    with open(both + '.json', 'w') as f:
        json.dump({'layout': 'HWT'}, f)
    with pytest.raises(SpikeFileError,
                       match='says layout HWT but its member "layout" says '
                       'THW'):
        load_spikes(both)
    for name, layout in (('word', 'thw'), ('list', ['THW', 'HWT']),
                         ('number', 1), ('bytes', b'TWH')):
        path = str(tmp_path / f'{name}.npz')
        np.savez(path, spikes=clip, layout=np.array(layout))
        with pytest.raises(SpikeFileError,
                           match=_path_in_message(path) + ': member '
                           '"layout"'):
            load_spikes(path)
    side = str(tmp_path / 'side.npy')
    np.save(side, clip)
    with open(side + '.json', 'w') as f:
        json.dump({'layout': 'TWH'}, f)
    with pytest.raises(SpikeFileError, match=re.escape(
            f'{side}: side file {side}.json says "layout": \'TWH\'; '
            f"expected one of ['THW', 'HWT']")):
        load_spikes(side)


def test_a_layout_member_declaring_a_huge_string_is_refused_unread(
        tmp_path):
    """The member's header is checked before its data: a header declaring
    a million-character string (or any array) allocates nothing."""
    import io
    import zipfile
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, dict(descr='<U1000000', fortran_order=False, shape=()))
    path = str(tmp_path / 'huge.npz')
    np.savez(path, spikes=_random_spikes((4, 2, 3)))
    with zipfile.ZipFile(path, 'a') as archive:
        archive.writestr('layout.npy', header.getvalue() + b'T\0\0\0')
    with pytest.raises(SpikeFileError, match='member "layout" is an array '
                       'of shape'):
        load_spikes(path)


@pytest.mark.parametrize('ext', ['.dat', '.spk'])
def test_packed_formats_store_frames_first(tmp_path, ext):
    clip = _random_spikes((5, 4, 6), seed=27)
    path = str(tmp_path / ('clip' + ext))
    save_spikes(path, clip)
    size = dict(height=4, width=6)
    np.testing.assert_array_equal(load_spikes(path, layout='THW', **size),
                                  clip)
    for read in (spike_shape, load_spikes):
        with pytest.raises(SpikeFileError, match=re.escape(
                f'{path}: a {ext} file stores frames one after another, '
                f'(T, H, W); layout HWT does not apply')):
            read(path, layout='HWT', **size)


def test_layout_argument_is_declared():
    for read in (spike_shape, load_spikes):
        with pytest.raises(ArgumentError, match="layout must be one of "
                           r"\['THW', 'HWT'\] or None, got 'thw'"):
            read('clip.npy', layout='thw')


def test_interleaved_npz_window_keeps_only_the_window(tmp_path):
    """(H, W, T) in C order stores each pixel's steps together: the member
    inflates whole (64 MiB of zeros, 64 kB on disk) but only the window
    and one chunk at a time are held."""
    import tracemalloc
    path = str(tmp_path / 'hwt.npz')
    _write_npz_bomb(path, (512, 512, 256))
    tracemalloc.start()
    window = load_spikes(path, start=100, length=9, layout='HWT')
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert window.shape == (9, 512, 512) and not window.any()
    # the window (2.25 MiB), a chunk and zipfile's buffers of it: far
    # from the 64 MiB member
    assert peak < 10 << 20, peak


def test_frame_major_fortran_hwt_npz_inflates_up_to_the_window(tmp_path,
                                                               inflated):
    """(H, W, T) in Fortran order stores frames one after another, as
    (T, H, W) in C order does: only the frames up to the window's end
    inflate."""
    path = str(tmp_path / 'f.npz')
    _write_npz_bomb(path, (64, 64, 256), fortran=True)  # (H, W, T)
    window = load_spikes(path, start=30, length=9, layout='HWT')
    assert window.shape == (9, 64, 64) and not window.any()
    assert 39 * 64 * 64 <= inflated[0] <= 39 * 64 * 64 + 1024


@pytest.mark.parametrize('name', ['rec.npy', 'rec.spk', 'rec.dat'])
def test_a_fifo_named_like_a_recording_is_refused_not_read(tmp_path, name):
    """A reader that opened it would wait for a writer forever."""
    import os
    os.mkfifo(tmp_path / name)
    with pytest.raises(SpikeFileError, match=f'{name}: not a regular file'):
        spike_shape(str(tmp_path / name), 4, 8)
    with pytest.raises(SpikeFileError, match=f'{name}: not a regular file'):
        load_spikes(str(tmp_path / name), 4, 8)


def test_a_fifo_as_a_side_file_is_refused_not_read(tmp_path):
    import os
    (tmp_path / 'rec.dat').write_bytes(bytes(8))
    os.mkfifo(tmp_path / 'rec.dat.json')
    with pytest.raises(ValueError, match='rec.dat.json: a .* is read from a '
                       'regular file'):
        load_spikes(str(tmp_path / 'rec.dat'))
