"""The Cityscapes -> Spike-Cityscapes converter on a tiny Cityscapes tree."""
import json
import multiprocessing
import os
import os.path as osp
import subprocess
import sys

import cv2
import killed_converter_run  # beside this file
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import wgse_mmseg.data_generation.cityscapes_conversion as conversion
from wgse_mmseg.core import simulation  # the converter calls it there
from wgse_mmseg.core.seeding import derive_seed
from wgse_mmseg.core.simulation import simulate_spikes
from wgse_mmseg.data_generation.cityscapes_conversion import (
    ConversionSettings, convert_cityscapes, load_scene, sample_effects)
from wgse_mmseg.data_generation.cityscapes_layout import (CITYSCAPES_LABELS,
                                                          LABEL_ID_TO_TRAIN_ID,
                                                          find_samples,
                                                          labelids_to_trainids,
                                                          resize_nearest)
from wgse_mmseg.data_generation.shards import WHOLE, Shard
from wgse_mmseg.datasets import SpikeCityscapesDataset
from wgse_mmseg.fileio.locks import own_folder
from wgse_mmseg.fileio.output_folder import MANIFEST_NAME
from wgse_mmseg.fileio.spike_files import load_spikes

REPO_ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
SIZE = (64, 128)  # source frames, H x W
SETTINGS = ConversionSettings(height=32, width=64, num_steps=9)
# stem -> (split, city, label files written, has a sequence)
SAMPLES = {
    'aachen_000000_000123': ('train', 'aachen', ('labelIds', ), True),
    'aachen_000001_000019': ('train', 'aachen',
                             ('labelIds', 'labelTrainIds'), False),
    'bonn_000000_000019': ('val', 'bonn', ('labelTrainIds', ), False),
}


def _write(path, image):
    os.makedirs(osp.dirname(path), exist_ok=True)
    assert cv2.imwrite(path, image)


def _image(rng, shift=0):
    """A smooth random colour image, shifted ``shift`` pixels to the right."""
    small = rng.integers(0, 256, (8, 16, 3), dtype=np.uint8)
    image = cv2.resize(small, SIZE[::-1], interpolation=cv2.INTER_CUBIC)
    return np.roll(image, shift, axis=1)


def make_cityscapes(root):
    """Write a tiny Cityscapes tree; return stem -> source label arrays."""
    labels = {}
    for index, (stem, (split, city, kinds, sequence)) in enumerate(
            SAMPLES.items()):
        rng = np.random.default_rng(index)
        image = _image(rng)
        _write(osp.join(root, 'leftImg8bit', split, city,
                        f'{stem}_leftImg8bit.png'), image)
        ids = np.array([i % 256 for i, _, _ in CITYSCAPES_LABELS], np.uint8)
        labels[stem] = dict(
            labelIds=rng.choice(ids, SIZE),
            # deliberately not the mapping of labelIds: it must be copied
            labelTrainIds=rng.choice([*range(19), 255], SIZE).astype(
                np.uint8))
        for kind in kinds:
            _write(osp.join(root, 'gtFine', split, city,
                            f'{stem}_gtFine_{kind}.png'),
                   labels[stem][kind])
        if sequence:  # 30 frames, the annotated one the 20th
            name, frame = stem.rsplit('_', 1)
            for offset in range(-19, 11):
                _write(osp.join(
                    root, 'leftImg8bit_sequence', split, city,
                    f'{name}_{int(frame) + offset:06d}_leftImg8bit.png'),
                    _image(np.random.default_rng(index), 3 * offset))
    return labels


def _files(out_dir):
    return sorted(
        osp.relpath(osp.join(d, f), out_dir)
        for d, _, files in os.walk(out_dir) for f in files
        if f != MANIFEST_NAME)


def _expected_files():
    return sorted(
        path for stem, (split, city, _, _) in SAMPLES.items() for path in (
            f'spike/{split}/{city}/{stem}_spike.spk',
            f'spike/{split}/{city}/{stem}_spike.json',
            f'gtFine/{split}/{city}/{stem}_gtFine_labelTrainIds.png'))


def _assert_same_files(out, other):
    """Every file under ``out`` has a byte-identical copy under ``other``."""
    for path in _files(out):
        with open(osp.join(out, path), 'rb') as a, \
                open(osp.join(other, path), 'rb') as b:
            assert a.read() == b.read(), path


@pytest.fixture
def calls(monkeypatch, single_thread):
    """Records the number of frames of each simulation."""
    recorded = []

    def recording(frames, num_steps, threshold, effects, seed):
        recorded.append(len(frames))
        return simulate_spikes(frames, num_steps, threshold=threshold,
                               effects=effects, seed=seed)

    monkeypatch.setattr(simulation, 'simulate_spikes', recording)
    return recorded


@pytest.fixture
def cityscapes(tmp_path):
    root = str(tmp_path / 'cityscapes')
    return root, make_cityscapes(root)


# ----------------------------------------------------------------- labels
def test_label_table_is_cityscapes():
    ids = [label_id for label_id, _, _ in CITYSCAPES_LABELS]
    assert sorted(ids) == list(range(-1, 34))
    train = sorted((t, name) for _, name, t in CITYSCAPES_LABELS
                   if 0 <= t < 255)
    assert [t for t, _ in train] == list(range(19))
    assert tuple(name for _, name in train) == tuple(
        SpikeCityscapesDataset.METAINFO['classes'])
    # by hand: road, sidewalk, car, bicycle, unlabeled, parking, -1 (255)
    for label_id, train_id in [(7, 0), (8, 1), (26, 13), (33, 18), (0, 255),
                               (9, 255), (255, 255)]:
        assert LABEL_ID_TO_TRAIN_ID[label_id] == train_id


def test_unknown_label_id_names_the_file():
    with pytest.raises(ValueError, match=r'x\.png.*\[40\]'):
        labelids_to_trainids(np.array([[7, 40]], np.uint8), 'x.png')


def test_resize_nearest_is_opencv_nearest():
    label = np.random.default_rng(0).integers(0, 256, (64, 128), np.uint8)
    assert np.array_equal(
        resize_nearest(label, 32, 64),
        cv2.resize(label, (64, 32), interpolation=cv2.INTER_NEAREST))


# ---------------------------------------------------------------- samples
def test_find_samples(cityscapes):
    root, _ = cityscapes
    samples = {s.stem: s for s in find_samples(root, ('train', 'val'))}
    assert set(samples) == set(SAMPLES)
    seq = samples['aachen_000000_000123']
    assert seq.label_kind == 'labelIds'
    assert [osp.relpath(p, root) for p in seq.sequence] == [
        f'{tree}/train/aachen/aachen_000000_{frame}_leftImg8bit.png'
        for tree, frame in [('leftImg8bit_sequence', '000122'),
                            ('leftImg8bit', '000123'),
                            ('leftImg8bit_sequence', '000124')]]
    assert samples['aachen_000001_000019'].label_kind == 'labelTrainIds'
    assert samples['bonn_000000_000019'].sequence == ()
    assert len(find_samples(root, ('train', ), 10)[0].sequence) == 21
    assert find_samples(root, ('train', ), 0)[0].sequence == ()


def test_missing_inputs_are_named(cityscapes):
    root, _ = cityscapes
    with pytest.raises(FileNotFoundError, match='leftImg8bit/test'):
        find_samples(root, ('test', ))
    label = osp.join(root, 'gtFine', 'val', 'bonn',
                     'bonn_000000_000019_gtFine_labelTrainIds.png')
    os.remove(label)
    with pytest.raises(FileNotFoundError,
                       match='bonn_000000_000019_leftImg8bit.png.*no label'):
        find_samples(root, ('val', ))
    frame = osp.join(root, 'leftImg8bit_sequence', 'train', 'aachen',
                     'aachen_000000_000124_leftImg8bit.png')
    os.remove(frame)
    with pytest.raises(FileNotFoundError, match='000124_leftImg8bit.png'):
        find_samples(root, ('train', ))


# ---------------------------------------------------------------- effects
def test_effects_per_model_and_scene_files(tmp_path, cityscapes):
    root, _ = cityscapes
    seq, static = find_samples(root, ('train', ))
    scene = {'camera_motion': {'translation': [8, 0], 'per': 'clip'},
             'shot_noise': None}
    assert sample_effects(seq, scene) == {
        'interpolation': {'method': 'flow'}, 'shot_noise': None}
    assert sample_effects(static, scene) == scene
    assert sample_effects(seq, {'interpolation': {'method': 'linear'}}) == {
        'interpolation': {'method': 'linear'}}
    assert sample_effects(static, {}) == {}
    (tmp_path / 's.yaml').write_text('shot_noise:\n')
    (tmp_path / 's.json').write_text(json.dumps(scene))
    assert load_scene(str(tmp_path / 's.yaml')) == {'shot_noise': None}
    assert load_scene(str(tmp_path / 's.json')) == scene
    assert load_scene('{"jitter": {}}') == {'jitter': {}}
    with pytest.raises(ValueError, match='neither a file nor inline JSON'):
        load_scene('nope.json')
    with pytest.raises(ValueError, match='unknown effect'):
        load_scene('{"blur": {}}')
    with pytest.raises(ValueError, match='electrons'):
        load_scene('{"shot_noise": {"electrons": -1}}')


# -------------------------------------------------------------- converter
def test_convert_layout_labels_spikes(tmp_path, cityscapes, calls):
    root, labels = cityscapes
    out = str(tmp_path / 'out')
    counts = convert_cityscapes(root, out, SETTINGS, progress=False)
    assert counts == dict(sequence=1, static=2, skipped=0)
    assert _files(out) == _expected_files()
    for stem, (split, city, kinds, sequence) in SAMPLES.items():
        source = labels[stem]['labelTrainIds' if 'labelTrainIds' in kinds
                              else 'labelIds']
        if 'labelTrainIds' not in kinds:
            source = LABEL_ID_TO_TRAIN_ID[source]
        label = cv2.imread(
            osp.join(out, 'gtFine', split, city,
                     f'{stem}_gtFine_labelTrainIds.png'),
            cv2.IMREAD_UNCHANGED)
        assert label.dtype == np.uint8
        assert np.array_equal(label, source[::2, ::2])  # nearest, exactly
        spikes = load_spikes(
            osp.join(out, 'spike', split, city, f'{stem}_spike.spk'))
        assert spikes.shape == (9, 32, 64) and spikes.dtype == np.uint8
        assert set(np.unique(spikes)) <= {0, 1} and spikes.any()
        with open(osp.join(out, 'spike', split, city,
                           f'{stem}_spike.json')) as f:
            meta = json.load(f)
        recipe = meta['recipe']
        assert meta['simulation']['resampling'] == (
            'flow' if sequence else 'static')
        assert recipe['model'] == ('sequence' if sequence else 'static')
        assert recipe['seed'] == derive_seed(0, stem)
        assert recipe['effects'] == (
            {'interpolation': {'method': 'flow'}} if sequence else {})
        assert recipe['time_span']['scene_seconds'] == pytest.approx(
            2 / 17 if sequence else 0)
    assert sorted(calls) == [1, 1, 3]
    # the dataset class reads the result
    dataset = SpikeCityscapesDataset(
        data_root=out, data_prefix=dict(img_path='spike/train',
                                        seg_map_path='gtFine/train'),
        pipeline=[], lazy_init=False)
    assert len(dataset) == 2


def test_resume_after_interruption(tmp_path, cityscapes, calls, monkeypatch):
    root, _ = cityscapes
    out = str(tmp_path / 'out')
    recording = simulation.simulate_spikes

    def interrupted(*args, **kwargs):
        if len(calls) == 1:
            raise KeyboardInterrupt
        return recording(*args, **kwargs)

    monkeypatch.setattr(simulation, 'simulate_spikes', interrupted)
    with pytest.raises(KeyboardInterrupt):
        convert_cityscapes(root, out, SETTINGS, progress=False)
    first = 'aachen_000000_000123'
    assert _files(out) == [p for p in _expected_files() if first in p]
    mtimes = {p: os.stat(osp.join(out, p)).st_mtime_ns for p in _files(out)}
    # what a SIGKILL mid-write leaves: atomic_output's temporary file
    stale = osp.join(out, 'spike', 'val', 'bonn',
                     '.tmp-bonn_000000_000019_spike.spk.k1lled_.spk')
    os.makedirs(osp.dirname(stale))
    open(stale, 'wb').close()

    monkeypatch.setattr(simulation, 'simulate_spikes', recording)
    del calls[:]
    counts = convert_cityscapes(root, out, SETTINGS, progress=False)
    assert counts == dict(sequence=0, static=2, skipped=1)
    assert len(calls) == 2 and _files(out) == _expected_files()
    assert mtimes == {p: os.stat(osp.join(out, p)).st_mtime_ns
                      for p in mtimes}

    # a truncated spike file and a deleted label are redone, nothing else
    spike = osp.join(out, 'spike', 'train', 'aachen', f'{first}_spike.spk')
    with open(spike, 'r+b') as f:
        f.truncate(40)
    os.remove(osp.join(out, 'gtFine', 'val', 'bonn',
                       'bonn_000000_000019_gtFine_labelTrainIds.png'))
    del calls[:]
    counts = convert_cityscapes(root, out, SETTINGS, progress=False)
    assert counts == dict(sequence=1, static=1, skipped=1)
    assert sorted(calls) == [1, 3]
    assert _files(out) == _expected_files()


def test_deterministic_and_settings_aware(tmp_path, cityscapes, calls):
    root, _ = cityscapes
    outs = [str(tmp_path / name) for name in ('a', 'b')]
    for out in outs:
        convert_cityscapes(root, out, SETTINGS, splits=('train', ),
                           progress=False)
    _assert_same_files(*outs)
    # other settings redo exactly the samples they change
    no_sequence = ConversionSettings(height=32, width=64, num_steps=9,
                                     frames_around=0)
    counts = convert_cityscapes(root, outs[0], no_sequence,
                                splits=('train', ), progress=False)
    assert counts == dict(sequence=0, static=1, skipped=1)
    lower_threshold = ConversionSettings(height=32, width=64, num_steps=9,
                                         threshold=1.0)
    counts = convert_cityscapes(root, outs[0], lower_threshold,
                                splits=('train', ), progress=False)
    assert counts == dict(sequence=1, static=1, skipped=0)


def test_cli_in_parallel_then_resume(tmp_path, cityscapes, single_thread):
    root, _ = cityscapes
    out = str(tmp_path / 'out')
    scene = {'camera_motion': {'translation': [8, 0], 'per': 'clip'}}
    script = osp.join(REPO_ROOT, 'tools', 'dataset_converters',
                      'spike_cityscapes.py')
    result = subprocess.run(
        [sys.executable, script, root, out, '--height', '32', '--width',
         '64', '--num-steps', '9', '--nproc', '2', '--limit', '1',
         '--scene', json.dumps(scene)],
        capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert '1 samples from sequences, 1 from the static model' in \
        result.stdout
    assert _files(out) == [p for p in _expected_files()
                           if 'aachen_000001' not in p]
    for stem, resampling in [('aachen_000000_000123', 'flow'),
                             ('bonn_000000_000019', 'camera_motion')]:
        split, city = SAMPLES[stem][:2]
        with open(osp.join(out, 'spike', split, city,
                           f'{stem}_spike.json')) as f:
            assert json.load(f)['simulation']['resampling'] == resampling
    # the same files from one process with other thread counts
    settings = ConversionSettings(height=32, width=64, num_steps=9,
                                  scene=scene)
    serial = str(tmp_path / 'serial')
    convert_cityscapes(root, serial, settings, limit=1, progress=False)
    _assert_same_files(out, serial)
    counts = convert_cityscapes(root, out, settings, progress=False)
    assert counts == dict(sequence=0, static=1, skipped=2)


def _samples_state(out):
    """stem -> the marker's seed, or None for a sample without a marker."""
    state = {}
    for stem, (split, city, _, _) in SAMPLES.items():
        marker = osp.join(out, 'spike', split, city, f'{stem}_spike.json')
        if osp.exists(marker):
            with open(marker) as f:
                state[stem] = json.load(f)['recipe']['seed']
        else:
            state[stem] = None
    return state


def _sample_bytes(out, stem):
    split, city = SAMPLES[stem][:2]
    paths = (f'spike/{split}/{city}/{stem}_spike.spk',
             f'spike/{split}/{city}/{stem}_spike.json',
             f'gtFine/{split}/{city}/{stem}_gtFine_labelTrainIds.png')
    return [open(osp.join(out, p), 'rb').read() for p in paths]


def _served(out, split, verify='size'):
    """Stems the dataset on ``out``'s ``split`` serves, and its skipped
    counts (reason -> count)."""
    try:
        dataset = SpikeCityscapesDataset(
            data_root=out, data_prefix=dict(img_path=f'spike/{split}',
                                            seg_map_path=f'gtFine/{split}'),
            pipeline=[], verify=verify)
    except FileNotFoundError as error:  # no sample served
        assert 'holds no sample' in str(error)
        return [], None
    stems = [osp.basename(dataset.get_data_info(i)['img_path'])[
        :-len('_spike.spk')] for i in range(len(dataset))]
    return stems, dataset.skipped


def test_dataset_serves_only_samples_whose_marker_matches(
        tmp_path, cityscapes, calls):
    from mmengine.logging import MMLogger
    root, _ = cityscapes
    out = str(tmp_path / 'out')
    convert_cityscapes(root, out, SETTINGS, progress=False)
    assert _served(out, 'train') == (
        ['aachen_000000_000123', 'aachen_000001_000019'], {})
    # a label replaced by other bytes of the same size: only the full check
    # sees it
    label = osp.join(out, 'gtFine', 'train', 'aachen',
                     'aachen_000001_000019_gtFine_labelTrainIds.png')
    with open(label, 'r+b') as f:
        data = f.read()
        f.seek(0)
        f.write(bytes(255 - b for b in data[:8]) + data[8:])
    assert _served(out, 'train')[0] == ['aachen_000000_000123',
                                        'aachen_000001_000019']
    assert _served(out, 'train', 'full') == (['aachen_000000_000123'],
                                             {'digest differs': 1})
    # a truncated spike file, a missing marker: skipped, counted, logged
    spike = osp.join(out, 'spike', 'train', 'aachen',
                     'aachen_000000_000123_spike.spk')
    with open(spike, 'r+b') as f:
        f.truncate(40)
    os.remove(osp.join(out, 'spike', 'val', 'bonn',
                       'bonn_000000_000019_spike.json'))
    logged = []
    logger = MMLogger.get_current_instance()
    handler = logger.handlers[0]
    emit = handler.emit
    handler.emit = lambda record: logged.append(record.getMessage())
    try:
        assert _served(out, 'train') == (['aachen_000001_000019'],
                                         {'size differs': 1})
    finally:
        handler.emit = emit
    assert any(f'{out}/spike/train: serving 1 of 2 samples; skipped 1' in m
               and '1 size differs' in m for m in logged), logged
    with pytest.raises(FileNotFoundError,
                       match=f'{out}/spike/val holds no sample.*1 no marker'):
        SpikeCityscapesDataset(
            data_root=out, data_prefix=dict(img_path='spike/val',
                                            seg_map_path='gtFine/val'),
            pipeline=[])
    assert _served(out, 'val', 'none') == (['bonn_000000_000019'], {})
    with pytest.raises(ValueError, match='verify must be one of'):
        SpikeCityscapesDataset(data_root=out, pipeline=[], verify='fast')


def test_an_empty_dataset_folder_is_named(tmp_path):
    for folder in ('spike/train', 'gtFine/train'):
        os.makedirs(tmp_path / folder)
    with pytest.raises(FileNotFoundError,
                       match=f'{tmp_path}/spike/train holds no sample'):
        SpikeCityscapesDataset(
            data_root=str(tmp_path),
            data_prefix=dict(img_path='spike/train',
                             seg_map_path='gtFine/train'), pipeline=[])


#: what the converter imports when it runs (the module imports them lazily)
_CONVERTER_IMPORTS = ('cv2', 'torch', simulation.__name__)


def _converter_killed_at(step, when, args):
    """:func:`killed_converter_run.run_killed_at` (the converter with
    ``args``, SIGKILLed just ``when`` its ``step``-th file-system step) in a
    child forked by multiprocessing's fork server, which imported the
    converter's modules once. Returns the child's exit code: -9 when
    killed, 0 when it finished first."""
    context = multiprocessing.get_context('forkserver')
    # The package's modules, not the helper beside this file: Python 3.11's
    # fork server imports its preloads without the test's sys.path (each
    # child then imports the helper, whose imports are loaded by then).
    context.set_forkserver_preload([conversion.__name__,
                                    *_CONVERTER_IMPORTS])
    child = context.Process(target=killed_converter_run.run_killed_at,
                            args=(step, when, args))
    child.start()
    child.join(120)
    if child.exitcode is None:
        child.kill()
        child.join()
        pytest.fail(f'the converter ({args}) ran for 120 s')
    return child.exitcode


@pytest.mark.long(15)
def test_converter_survives_sigkill(tmp_path, cityscapes, single_thread):
    """24 runs killed at random file-system steps, alternating between two
    settings over a finished conversion: after every kill, each sample with
    a marker is byte-identical to a clean conversion with the marker's
    settings (no partial, no stale sample), the dataset on the folder serves
    exactly those and counts the others as skipped; a last run finishes
    it."""
    import shutil
    root, _ = cityscapes
    refs = {}
    for base_seed in (0, 1):
        settings = ConversionSettings(height=32, width=64, num_steps=9,
                                      seed=base_seed)
        refs[base_seed] = str(tmp_path / f'ref{base_seed}')
        convert_cityscapes(root, refs[base_seed], settings, progress=False)
    seed_of = {derive_seed(base, stem): base for stem in SAMPLES
               for base in (0, 1)}
    out = str(tmp_path / 'out')
    shutil.copytree(refs[0], out)
    rng = np.random.default_rng(0)
    killed = skips = 0
    for run in range(24):
        base_seed = run % 2
        step = int(rng.integers(1, 13))  # 3 samples x 4 steps at most
        when = str(rng.choice(['before', 'after']))
        code = _converter_killed_at(step, when, [
            root, out, '--height', '32', '--width', '64', '--num-steps', '9',
            '--seed', str(base_seed)])
        assert code in (0, -9), f'run {run}: exit code {code} (stderr above)'
        killed += code == -9
        state = _samples_state(out)
        for stem, seed in state.items():
            if seed is not None:
                assert _sample_bytes(out, stem) == _sample_bytes(
                    refs[seed_of[seed]], stem), (run, stem)
        for split in ('train', 'val'):
            stems = [stem for stem in SAMPLES if SAMPLES[stem][0] == split]
            marked = [stem for stem in stems if state[stem] is not None]
            served, skipped = _served(out, split)
            assert served == marked, (run, split)
            unmarked = len(stems) - len(marked)
            if served:
                assert sum((skipped or {}).values()) == unmarked, run
        skips += sum(seed is None for seed in state.values())
    assert killed >= 20 and skips > 0
    counts = convert_cityscapes(root, out, ConversionSettings(
        height=32, width=64, num_steps=9, seed=1), progress=False)
    assert sum(counts.values()) == len(SAMPLES)
    assert _files(out) == _expected_files()  # no temporary file is left
    for stem in SAMPLES:
        assert _sample_bytes(out, stem) == _sample_bytes(refs[1], stem)


# ----------------------------------------------------------------- shards
@given(count=st.integers(0, 40), parts=st.integers(1, 9))
def test_shards_partition_a_job_in_order(count, parts):
    items = list(range(count))
    shards = [Shard(k, parts).select(items) for k in range(1, parts + 1)]
    assert sorted(sum(shards, [])) == items  # disjoint and complete
    for k, part in enumerate(shards, 1):
        assert part == sorted(part)
        assert all(i % parts == k - 1 for i in part)
    assert WHOLE.select(items) == items


BAD_SHARDS = ['0/2', '3/2', '1/0', 'a/b', '1', '1/2/3', '-1/2', '']


def test_a_bad_shard_is_refused_naming_the_option(tmp_path, load_tool,
                                                  capsys):
    """Every bad ``--shard`` ends the tool's parsing with status 2 and the
    option's message; one run of the script shows it exits so before
    writing anything; the function refuses one as well."""
    parser = load_tool('tools/dataset_converters/spike_cityscapes.py'
                       ).build_parser()
    for text in BAD_SHARDS:
        with pytest.raises(SystemExit) as exit_:
            parser.parse_args([str(tmp_path), str(tmp_path / 'out'),
                               f'--shard={text}'])
        assert exit_.value.code == 2, text
        assert 'argument --shard: must be K/N with 1 <= K <= N' in \
            capsys.readouterr().err, text
    script = osp.join(REPO_ROOT, 'tools', 'dataset_converters',
                      'spike_cityscapes.py')
    proc = subprocess.run(
        [sys.executable, script, str(tmp_path), str(tmp_path / 'out'),
         f'--shard={BAD_SHARDS[0]}'], capture_output=True, text=True,
        timeout=300)
    assert proc.returncode == 2
    assert 'argument --shard: must be K/N with 1 <= K <= N' in proc.stderr
    assert not (tmp_path / 'out').exists()
    with pytest.raises(ValueError, match='convert_cityscapes: shard must be'):
        convert_cityscapes(str(tmp_path), str(tmp_path / 'out'),
                           shard=(3, 2), progress=False)


def test_shards_on_a_slurm_array_equal_one_run(tmp_path, cityscapes,
                                               single_thread):
    """Two array tasks of tools/slurm_convert.sh, at the same time into one
    folder, write byte-identical files to one run's; a stale temporary of
    a sample of one shard is removed by that shard, another process's
    temporary beside it is left alone."""
    root, _ = cityscapes
    settings = ConversionSettings(height=32, width=64, num_steps=9,
                                  scene={'shot_noise': {}})
    single = str(tmp_path / 'single')
    convert_cityscapes(root, single, settings, progress=False)
    out = str(tmp_path / 'sharded')
    with own_folder(out):  # killed runs' folder, with their temporaries
        pass
    city = osp.join(out, 'spike', 'val', 'bonn')
    os.makedirs(city)
    stale = osp.join(city, '.tmp-bonn_000000_000019_spike.spk.abc_12.spk')
    foreign = osp.join(city, '.tmp-other_000000_000019_spike.spk.abc_12.spk')
    for path in (stale, foreign):
        open(path, 'wb').close()
    env = dict(os.environ, OMP_NUM_THREADS='1', SLURM_ARRAY_TASK_MIN='0',
               SLURM_ARRAY_TASK_COUNT='2', SLURM_SUBMIT_DIR=REPO_ROOT,
               PYTHON=sys.executable)
    env.pop('TRITON_INTERPRET', None)
    tasks = [subprocess.Popen(
        ['bash', osp.join(REPO_ROOT, 'tools', 'slurm_convert.sh'), root, out,
         '--height', '32', '--width', '64', '--num-steps', '9', '--scene',
         json.dumps(settings.scene)],
        env=dict(env, SLURM_ARRAY_TASK_ID=str(task)), stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True) for task in (0, 1)]
    outputs = [task.communicate(timeout=600) for task in tasks]
    for task, (stdout, stderr) in zip(tasks, outputs):
        assert task.returncode == 0, stderr
    # sorted samples: aachen_000000 (train), aachen_000001, bonn (val)
    assert '(shard 1/2): 1 samples from sequences, 1 from the static' in \
        outputs[0][0]
    assert '(shard 2/2): 0 samples from sequences, 1 from the static' in \
        outputs[1][0]
    assert not osp.exists(stale) and osp.exists(foreign)
    os.remove(foreign)
    assert _files(out) == _files(single) == _expected_files()
    _assert_same_files(out, single)
    # a shard run again finds its samples done
    counts = convert_cityscapes(root, out, settings, progress=False,
                                shard=Shard(2, 2))
    assert counts == dict(sequence=0, static=0, skipped=1)


def test_a_shard_has_one_writer_and_no_link_is_followed(tmp_path, cityscapes,
                                                        calls):
    """A process converting a shard excludes another on the same shard
    (named), not one on another shard; a link at a sample's file is
    replaced with the sample, its target untouched; the Cityscapes input
    and the dataset's listing take each image once whatever links lead to
    it, and a folder linking to itself does not stop the listing."""
    from wgse_mmseg.fileio.input_guard import OutputFolderError
    from wgse_mmseg.fileio.locks import own_folder
    root, _ = cityscapes
    out = str(tmp_path / 'out')
    with own_folder(out, 'shard-1-of-2'):
        with pytest.raises(OutputFolderError,
                           match=r'out: another process is writing this '
                           rf'output \(process {os.getpid()} on host'):
            convert_cityscapes(root, out, SETTINGS, progress=False,
                               shard=(1, 2))
        # shard 2/2 (aachen_000001) is another job
        assert convert_cityscapes(root, out, SETTINGS, progress=False,
                                  shard=(2, 2))['static'] == 1
    outside = tmp_path / 'precious.png'
    outside.write_bytes(b'keep me')
    label = osp.join(out, 'gtFine', 'val', 'bonn',
                     'bonn_000000_000019_gtFine_labelTrainIds.png')
    os.makedirs(osp.dirname(label))
    os.symlink(outside, label)
    # links in the input: a city linked twice, a folder linking to itself
    os.symlink('aachen', osp.join(root, 'leftImg8bit', 'train', 'zz_again'))
    os.symlink('.', osp.join(root, 'leftImg8bit', 'train', 'aachen', 'l1'))
    os.symlink('.', osp.join(root, 'leftImg8bit', 'train', 'aachen', 'l2'))
    counts = convert_cityscapes(root, out, SETTINGS, progress=False)
    assert counts == dict(sequence=1, static=1, skipped=1)
    assert outside.read_bytes() == b'keep me' and not osp.islink(label)
    assert _files(out) == _expected_files()
    os.symlink('.', osp.join(out, 'spike', 'train', 'aachen', 'loop'))
    os.symlink('aachen', osp.join(out, 'spike', 'train', 'twin'))
    dataset = SpikeCityscapesDataset(
        data_root=out, data_prefix=dict(img_path='spike/train',
                                        seg_map_path='gtFine/train'),
        pipeline=[], lazy_init=False)
    assert sorted(osp.basename(dataset.get_data_info(i)['img_path'])
                  for i in range(len(dataset))) == [
        'aachen_000000_000123_spike.spk', 'aachen_000001_000019_spike.spk']
