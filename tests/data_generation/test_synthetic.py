"""The embedded synthetic street-scene dataset: layout, resume, settings."""
import os

import numpy as np
import pytest

from wgse_mmseg.fileio.spike_files import load_spikes, spike_shape
from wgse_mmseg.fileio.output_folder import MANIFEST_NAME
from wgse_mmseg.data_generation.synthetic import (make_synthetic_dataset,
                                                  render_street_scene)
from wgse_mmseg.data_generation.views import render_trajectory


def _tree(out):
    return sorted(os.path.relpath(os.path.join(d, f), out)
                  for d, _, files in os.walk(out) for f in files
                  if f != MANIFEST_NAME)


def test_resume_keeps_done_samples_and_redoes_stale_ones(tmp_path):
    out = str(tmp_path / 'synth')
    args = dict(num_train=2, num_val=1, height=16, width=32, progress=False)
    assert make_synthetic_dataset(out, num_steps=9, **args) == 3
    tree = _tree(out)
    assert len(tree) == 9  # spikes, label and marker per sample
    assert make_synthetic_dataset(out, num_steps=9, **args) == 0
    # a truncated stream and a lost marker are redone
    spike = os.path.join(out, 'spike', 'train', 'synth',
                         'synth_000000_000019_spike.spk')
    with open(spike, 'r+b') as f:
        f.truncate(30)
    os.remove(os.path.join(out, 'spike', 'val', 'synth',
                           'synth_000002_000019_spike.json'))
    assert make_synthetic_dataset(out, num_steps=9, **args) == 2
    assert load_spikes(spike).shape == (9, 16, 32)
    # other settings in the same directory redo every sample
    assert make_synthetic_dataset(out, num_steps=11, **args) == 3
    assert spike_shape(spike) == (11, 16, 32)
    assert _tree(out) == tree


def test_the_dataset_folder_is_owned(tmp_path):
    """A link at a sample's file is replaced (its target kept), a linked
    folder inside is refused naming it, a second writer is refused naming
    the first, and no lock file is left."""
    import pytest
    from wgse_mmseg.fileio.input_guard import OutputFolderError
    from wgse_mmseg.fileio.locks import own_folder
    out = tmp_path / 'synth'
    args = dict(num_train=1, num_val=1, height=16, width=32, num_steps=9,
                progress=False)
    outside = tmp_path / 'precious.spk'
    outside.write_bytes(b'keep me')
    with own_folder(str(out)):  # a run killed before any sample
        pass
    folder = out / 'spike' / 'train' / 'synth'
    folder.mkdir(parents=True)
    spike = folder / 'synth_000000_000019_spike.spk'
    os.symlink(outside, spike)
    assert make_synthetic_dataset(str(out), **args) == 2
    assert outside.read_bytes() == b'keep me'
    assert not os.path.islink(spike) and spike_shape(str(spike)) == (9, 16,
                                                                     32)
    assert sorted(os.listdir(out)) == [MANIFEST_NAME, 'gtFine', 'spike']
    with own_folder(str(out)):
        with pytest.raises(OutputFolderError,
                           match=f'process {os.getpid()} on host'):
            make_synthetic_dataset(str(out), **args)
    elsewhere = tmp_path / 'elsewhere'
    elsewhere.mkdir()
    os.rename(out / 'gtFine' / 'val', elsewhere / 'val')
    os.symlink(elsewhere / 'val', out / 'gtFine' / 'val')
    with pytest.raises(OutputFolderError,
                       match=r'gtFine/val: a symbolic link'):
        make_synthetic_dataset(str(out), **dict(args, num_steps=11))
    assert len(os.listdir(elsewhere / 'val' / 'synth')) == 1


def test_the_frames_of_a_scene_are_bounded_as_a_product(monkeypatch):
    monkeypatch.setenv('WGSE_MMSEG_ALLOCATION_LIMIT', str(5 * 16 * 24 * 8))
    rng = np.random.default_rng(0)
    frames, _ = render_street_scene(rng, 16, 24, 5)
    assert frames.shape == (5, 16, 24)
    with pytest.raises(ValueError, match=r'the 6 x 16 x 24 float64 frames '
                       r'of a synthetic scene would take 18432 bytes'):
        render_street_scene(rng, 16, 24, 6)
    image = np.zeros((32, 32), np.float32)
    monkeypatch.setenv('WGSE_MMSEG_ALLOCATION_LIMIT', str(7 * 8 * 8 * 4))
    assert render_trajectory(image, (8, 8), 7, rng).shape == (7, 8, 8)
    with pytest.raises(ValueError, match=r'the 9 x 8 x 8 float32 frames of '
                       r'a trajectory would take 2304 bytes'):
        render_trajectory(image, (8, 8), 9, rng)
