"""Every declared argument of every public entry point, fuzzed.

For each argument that an entry point declares
(:mod:`wgse_mmseg.core.arguments`), hypothesis draws wrong types, NaN, Inf,
negative, zero, huge and fractional numbers, strings with quotes and
backslashes and, for paths, a directory, an empty file, a text file and a
missing file. The call must either give a project error (raised in this
package) that names the entry point and the argument, or a file error naming
the file, or succeed, within time and memory bounds.
"""
import importlib
import inspect
import math
import os
import os.path as osp
import pkgutil
import shutil

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wgse_bench
import wgse_mmseg
from wgse_mmseg.core.arguments import LAYOUT, ArgumentError, Choice, Path
from wgse_mmseg.data_generation.cityscapes_conversion import ConversionSettings

wgse_mmseg.register_all_modules()

#: the packages whose entry points are fuzzed
PACKAGES = (wgse_mmseg, wgse_bench)
PACKAGE_NAMES = tuple(package.__name__ for package in PACKAGES)


def _declared_entry_points():
    """``(callable, declaration)`` of every entry point that :func:`declare`
    checks, found in every module of the library and of the measurement
    wing: a function, or a class whose ``__init__`` is declared, defined in
    the module that holds it (a module whose optional dependency is absent
    is skipped)."""
    found = []
    infos = [info for package in PACKAGES for info in pkgutil.walk_packages(
        package.__path__, package.__name__ + '.')]
    for info in infos:
        try:
            module = importlib.import_module(info.name)
        except ModuleNotFoundError as err:
            if err.name and err.name.split('.')[0] not in PACKAGE_NAMES:
                continue
            raise
        for value in vars(module).values():
            function = (vars(value).get('__init__')
                        if inspect.isclass(value) else value)
            declaration = getattr(function, 'declaration', None)
            if declaration is not None and \
                    getattr(value, '__module__', None) == info.name:
                found.append((value, declaration))
    return sorted(found, key=lambda pair: (pair[0].__module__,
                                           pair[1].entry))


DECLARED = _declared_entry_points()

#: seconds and bytes of peak memory one call may add (generous: a refusal
#: takes microseconds, and accepted values build small modules)
TIME_BOUND_S = 20
MEMORY_BOUND = 1 << 30

# a tiny image folder, a spike file and an output folder for entry points
# that need them
FIXTURE_FILES = {}


@pytest.fixture(scope='module', autouse=True)
def _files(tmp_path_factory, wrong_file_kinds):
    import cv2
    from wgse_mmseg.fileio.spike_files import save_spikes
    root = tmp_path_factory.mktemp('fuzz')
    (root / 'images').mkdir()
    cv2.imwrite(str(root / 'images' / 'a.png'),
                np.full((12, 16), 128, np.uint8))
    save_spikes(str(root / 'clip.npy'), np.zeros((9, 4, 6), np.uint8))
    # a Cityscapes root of one annotated frame
    for tree, suffix, value in [('leftImg8bit', 'leftImg8bit', 128),
                                ('gtFine', 'gtFine_labelIds', 7)]:
        city = root / 'cityscapes' / tree / 'train' / 'aachen'
        city.mkdir(parents=True)
        cv2.imwrite(str(city / f'aachen_000000_000019_{suffix}.png'),
                    np.full((16, 32), value, np.uint8))
    FIXTURE_FILES.update(wrong_file_kinds, root=root,
                         images=str(root / 'images'),
                         clip=str(root / 'clip.npy'),
                         cityscapes=str(root / 'cityscapes'))
    yield


def _required(entry):
    """Valid values for arguments an entry point has no default for, and
    for those whose defaults would make an accepted call slow."""
    files = FIXTURE_FILES
    frames = np.full((2, 4, 6), 0.5)
    return {
        'SimulateSpikes': dict(num_steps=9),
        'simulate_spikes': dict(frames=frames, num_steps=9),
        'load_spikes': dict(path=files['clip']),
        'spike_shape': dict(path=files['clip']),
        'save_spikes': dict(path=str(files['root'] / 'out.npy'),
                            spikes=np.zeros((2, 2, 4), np.uint8)),
        'make_synthetic_dataset': dict(
            out_dir=str(files['root'] / 'synthetic'), num_train=1,
            num_val=0, height=16, width=16, num_steps=3, num_frames=2,
            progress=False),
        'SpikeRandomCrop': dict(crop_size=(4, 4)),
        'ResidualBlock': dict(channels=4),
        'SimulatedSpikeImageDataset': dict(
            image_dir=files['images'], num_samples=2, crop_size=(8, 8),
            num_steps=5, max_side=32, pipeline=[], lazy_init=True),
        'REDSSpikeDataset': dict(pipeline=[], lazy_init=True),
        'SpikeCityscapesDataset': dict(pipeline=[], lazy_init=True),
        'SpikeReconstructor': dict(num_steps=9, channels=8, num_blocks=1,
                                   mid_channels=4),
        'WGSE': dict(hidden_channels=4),
        'BandNetwork': dict(hidden_channels=4),
        'ExperimentSettings': dict(grid=files['clip'], data_root='data',
                                   work_dir='work', seeds=[0], epochs=1),
        'auto_exposure': dict(image=frames[0]),
        'apply_exposure': dict(image=frames[0]),
        'convert_cityscapes': dict(
            root=files['cityscapes'], out_dir=str(files['root'] / 'spikes'),
            settings=ConversionSettings(height=8, width=16, num_steps=3,
                                        frames_around=0),
            splits=('train',), progress=False),
        'time_calls': dict(fn=lambda: None, device=torch.device('cpu'),
                           repeat=1, warmup=0),
        'schedule_options': dict(epochs=None, max_iters=10),
        'band_lengths': dict(length=16, wavelet='haar'),
        'analysis_matrix': dict(length=16, wavelet='haar'),
        'synthesis_matrix': dict(lengths=(8, 8), wavelet='haar'),
        'wavedec': dict(data=torch.zeros(2, 16), wavelet='haar'),
        'waverec': dict(coeffs=[torch.zeros(2, 8)] * 2, wavelet='haar'),
        'tfp': dict(spikes=np.zeros((3, 4, 5))),
        'tfi': dict(spikes=np.zeros((3, 4, 5))),
        'tfi_spatial_mean': dict(spikes=np.zeros((3, 4, 5))),
        'tfi_temporal_mean': dict(spikes=np.zeros((3, 4, 5))),
        'export_training_images': dict(out_dir=str(files['root'] / 'images'),
                                       sources=('matplotlib',)),
        'score_recording': dict(path=files['clip'], methods=['tfp'],
                                num_steps=5),
        'ssim': dict(pred=np.full((12, 12), 0.5), gt=np.full((12, 12), 0.5)),
        'plan_walk': dict(total=100, length=9, stride=10),
        'walk_recording': dict(
            path=files['clip'], video=str(files['root'] / 'walk.gif'),
            model=lambda spikes: spikes.mean(1),
            render=lambda window, rate: np.zeros((4, 6), np.uint8),
            length=3, stride=2, progress=False),
        'export_onnx': dict(graph=torch.nn.Identity(),
                            path=str(files['root'] / 'model.onnx'),
                            num_steps=2, height=4, width=4),
        'measure_deployment': dict(name='x', config=files['missing'],
                                   cfg_options=None, shape=(2, 4, 4)),
    }.get(entry, {})


ENTRIES = [pytest.param(call, declaration, name,
                        id=f'{declaration.entry}.{name}')
           for call, declaration in DECLARED
           for name in declaration.arguments]


def test_the_public_entry_points_are_declared():
    entries = {declaration.entry for _, declaration in DECLARED}
    assert {
        'WGSE', 'BandNetwork', 'TFP', 'TemporalMeanFilter',
        'SpatialMeanFilter', 'SpikeSegDataPreProcessor', 'LoadSpikeFromFile',
        'SpikeRandomCrop', 'SpikeRandomFlip', 'SimulateSpikes',
        'LoadSpikeImagePair', 'SimulatedSpikeImageDataset',
        'REDSSpikeDataset', 'SpikeReconstructor', 'ResidualBlock',
        'load_spikes', 'spike_shape', 'save_spikes', 'simulate_spikes',
        'make_synthetic_dataset', 'ConversionSettings', 'convert_cityscapes',
        'SpikeCityscapesDataset', 'auto_exposure', 'apply_exposure',
        'time_calls', 'schedule_options', 'wavedec', 'waverec',
        'analysis_matrix', 'band_lengths', 'synthesis_matrix', 'tfp', 'tfi',
        'tfi_spatial_mean', 'tfi_temporal_mean', 'export_training_images',
        'ExperimentSettings', 'score_recording'
    } <= entries
    for _, declaration in DECLARED:
        parameters = inspect.signature(declaration.function).parameters
        required = {n for n, p in parameters.items()
                    if p.default is p.empty and n != 'self' and
                    p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)}
        assert required <= set(_required(declaration.entry)), (
            f'{declaration.entry}: give the test valid values of '
            f'{sorted(required)}')


def test_every_reader_of_a_recording_declares_the_layout():
    """One declared kind for the layout of a recording, ``'THW'`` or
    ``'HWT'`` or ``None`` (what the file records), on every entry point
    that reads one."""
    readers = {'load_spikes', 'spike_shape', 'LoadSpikeFromFile',
               'LoadSpikeImagePair', 'score_recording', 'walk_recording'}
    declaring = {declaration.entry for _, declaration in DECLARED
                 if 'layout' in declaration.arguments}
    assert declaring == readers
    for _, declaration in DECLARED:
        if declaration.entry in readers:
            layout = declaration.arguments['layout']
            assert isinstance(layout, Choice) and layout.optional
            assert layout.choices == LAYOUT.choices == ('THW', 'HWT')
            parameter = inspect.signature(
                declaration.function).parameters['layout']
            assert parameter.default is None, declaration.entry


def _bad_values(argument):
    """What a careless or hostile caller passes."""
    numbers = st.one_of(
        st.sampled_from([math.nan, math.inf, -math.inf, 0, 0.0, -1, -0.5,
                         2**31, 10**8, 10**18, 1e300, True, False]),
        st.integers(max_value=-1), st.integers(min_value=2**40),
        st.floats(min_value=0.01, max_value=1e6).filter(
            lambda v: not v.is_integer()))
    others = st.one_of(
        st.sampled_from([None, [], {}, (), b'bytes', 1j, object(),
                         [math.nan, 1], (1, 2, 3), ('a', 'b')]),
        st.text(alphabet='\'"\\ab/.\0', max_size=8))
    files = st.sampled_from(['directory', 'empty', 'text', 'missing']).map(
        lambda kind: FIXTURE_FILES[kind])
    if isinstance(argument, Path):  # mostly wrong file kinds for paths
        return st.one_of(files, files, numbers, others)
    return st.one_of(numbers, others, files)


@pytest.mark.parametrize('call, declaration, name', ENTRIES)
def test_bad_arguments(call, declaration, name, single_thread,
                       monkeypatch, bounded):
    # relative paths drawn for outputs land in the fixture folder
    monkeypatch.chdir(FIXTURE_FILES['root'])
    argument = declaration.arguments[name]

    @settings(max_examples=6, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(value=_bad_values(argument))
    def check(value):
        # 'missing' stays missing: an example that fuzzed an output with it
        # rightly created it, and a later input would find a file there
        _remove(FIXTURE_FILES['missing'])
        kwargs = dict(_required(declaration.entry), **{name: value})
        accepted = argument.accepts(value) or (value is None and
                                               argument.optional)
        try:
            with bounded(TIME_BOUND_S, MEMORY_BOUND):
                call(**kwargs)
        except ArgumentError as err:
            assert err.entry == declaration.entry, err
            assert name in err.argument, err
            assert 'wgse_mmseg/core/arguments.py' in \
                _traceback_files(err)[-1]
        except (ValueError, TypeError, OSError) as err:
            # a file the reader refused, named; or a relation between
            # arguments, named; a value the declaration accepts lets the
            # call go on to the other arguments, which may stop it (a
            # missing file among the required ones), named by the package
            message = str(err)
            assert accepted or (isinstance(value, str) and value in message) \
                or name in message, f'{type(err).__name__}: {message}'
            raised_in = _traceback_files(err)[-1]
            assert any(package in raised_in for package in PACKAGE_NAMES), (
                raised_in, message)
        else:
            assert accepted, (
                f'{declaration.entry}({name}={value!r}) was accepted but '
                f'the declaration refuses it')

    check()


def _remove(path: str) -> None:
    if osp.isdir(path) and not osp.islink(path):
        shutil.rmtree(path)
    elif osp.lexists(path):
        os.remove(path)


def _traceback_files(err):
    tb = err.__traceback__
    files = []
    while tb is not None:
        files.append(tb.tb_frame.f_code.co_filename.replace('\\', '/'))
        tb = tb.tb_next
    return files


def test_an_argument_error_crosses_a_process_boundary():
    """Pickled (as a spawned worker returns it) it keeps its class, message
    and parts; unpicklable, it used to break the benchmark's process pool."""
    import pickle
    from wgse_mmseg.core.arguments import ArgumentError
    error = ArgumentError('WGSE', 'level', 'an integer >= 1', 10**6)
    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is ArgumentError and str(copy) == str(error)
    assert (copy.entry, copy.argument, copy.expected) == (
        'WGSE', 'level', 'an integer >= 1')
