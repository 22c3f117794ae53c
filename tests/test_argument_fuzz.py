"""Every argument of every public entry point, fuzzed.

The entry points are found from the public API, not from the code that
checks them: every function and class in the ``__all__`` of a public module
of the library and of the measurement wing, and every class the package
registers in an MMSeg or mmengine registry, each with the parameters of
``inspect.signature``. For each parameter that takes a plain value (by its
default or the valid value given here: a number, a string, a flag, a path,
``None`` or a sequence of those; not a config, a tensor or a callable),
hypothesis draws wrong types, NaN, Inf, negative, zero, huge and fractional
numbers, strings with quotes and backslashes, and a directory, an empty
file, a text file and a missing file. The call either succeeds, within time
and memory bounds, or raises the package's clear error: an
:class:`~wgse_mmseg.argument_checks.ArgumentError` naming the entry point
and the parameter, or a ``ValueError``/``TypeError``/``OSError`` raised in
the package (never deep in torch, NumPy or the standard library) naming the
parameter or the file. A value no plain parameter takes (NaN, Inf, an
``object()``, a complex number, bytes) is never accepted.
"""
import collections
import importlib
import inspect
import math
import os
import os.path as osp
import pathlib
import pkgutil
import re
import shutil

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wgse_bench
import wgse_mmseg
from wgse_mmseg.argument_checks import ArgumentError
from wgse_mmseg.data_generation.cityscapes_conversion import ConversionSettings
from wgse_mmseg.errors import WgseError

wgse_mmseg.register_all_modules()

#: the packages whose entry points are fuzzed
PACKAGES = (wgse_mmseg, wgse_bench)
PACKAGE_NAMES = tuple(package.__name__ for package in PACKAGES)
PACKAGE_DIRS = tuple(osp.dirname(package.__file__).replace('\\', '/') + '/'
                     for package in PACKAGES)

#: public entry points the test does not call, and why
NOT_CALLED = {
    'register_all_modules': 'takes no arguments',
    'load_config': 'reads an MMSeg config '
                   '(tests/utils/test_config_options.py)',
    'spike_config': 'combines MMSeg configs (tests/utils/test_spike_model.py)',
    'SpikeRunner': "mmengine's Runner; its arguments are mmengine's",
    'CPUDistributedDataParallel': "torch's DistributedDataParallel on CPU, "
                                  'built by the runner',
    'SpikeSegInferencer': "MMSeg's inferencer over a built model "
                          '(tests/apis/test_inference.py)',
    'OnnxSpikeSegmentor': 'needs an exported model '
                          '(tests/apis/test_onnx_export.py)',
    'load_segmentor': 'a config and a checkpoint of a trained segmentor '
                      '(tests/apis/test_segmentor_checkpoint.py)',
    'WalkReport': 'the record walk_recording returns',
    'aggregate': 'reads the runs of an experiment grid (tests/bench)',
    'loss_change': 'reads a training curve (tests/bench)',
    'select': 'filters the entries of a grid file (tests/bench)',
    'report': 'renders the runs of an experiment grid (tests/bench)',
    'benchmark_entry': 'times a trained run of a grid (tests/bench)',
    'finished': 'reads a run of a grid (tests/bench)',
    'plan': 'plans the runs of a grid (tests/bench)',
    'run_one': 'trains a run of a grid (tests/bench)',
    'run_report': 'measures the GPU report on a GPU (dev/gpu_report.py)',
    'write_report': 'writes a measured GPU report (tests/bench)',
    'benchmark': 'scores a REDS folder with a trained model (tests/bench)',
    'benchmark_config': 'builds and times a whole segmentor (tests/bench)',
    'count_flops': 'counts a built segmentor (tests/bench)',
    'measure_enhancer_step': 'times a built segmentor (tests/bench)',
    'measure_latency': 'times a built segmentor (tests/bench)',
    'measure_throughput': 'times a built segmentor (tests/bench)',
    'measure_train_step': 'times a built segmentor (tests/bench)',
    'model_bases': 'tries every model base of MMSeg (tests/bench)',
    'try_model_base': 'builds an MMSeg model base (tests/bench)',
}
#: parameters handed to OpenMMLab as they are, which it checks
PASSED_THROUGH = {
    'ReconstructionMetric': {'collect_device', 'prefix', 'collect_dir'},
}
#: annotations of parameters that take no plain value
NOT_PLAIN = re.compile(r'Callable|Dict|dict|Module|Mapping|Config|Tensor|'
                       r'ndarray|Graph|device')


def _public_modules(package):
    """``package`` and every module of it whose dotted name has no part
    starting with ``_`` (a module whose optional dependency is absent is
    left out)."""
    yield package
    for info in pkgutil.walk_packages(package.__path__,
                                      package.__name__ + '.'):
        if any(part.startswith('_') for part in info.name.split('.')):
            continue
        try:
            yield importlib.import_module(info.name)
        except ModuleNotFoundError as err:
            if err.name and err.name.split('.')[0] in PACKAGE_NAMES:
                raise


def _registered():
    """Every class of the package in an MMSeg or mmengine registry."""
    import mmengine.registry
    import mmseg.registry
    for module in (mmengine.registry, mmseg.registry):
        for registry in vars(module).values():
            if isinstance(registry, mmengine.registry.Registry):
                for value in registry.module_dict.values():
                    if getattr(value, '__module__', '').startswith(
                            PACKAGE_NAMES):
                        yield value


def _is_entry_point(value) -> bool:
    """A function or a class the package defines, not an error class (the
    errors are held by test_errors.py)."""
    if not (inspect.isfunction(value) or inspect.isclass(value)):
        return False
    if inspect.isclass(value) and issubclass(value, BaseException):
        return False
    return getattr(value, '__module__', '').startswith(PACKAGE_NAMES)


def _public_entry_points():
    """``name -> callable`` of every public entry point."""
    found = {}
    for package in PACKAGES:
        for module in _public_modules(package):
            for name in getattr(module, '__all__', ()):
                value = getattr(module, name)
                if _is_entry_point(value):
                    found[value.__name__] = value
    for value in _registered():
        if _is_entry_point(value):
            found[value.__name__] = value
    return dict(sorted(found.items()))


ENTRY_POINTS = _public_entry_points()

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
    """Valid values for the parameters an entry point has no default for,
    and for those whose defaults would make an accepted call slow."""
    from wgse_mmseg.models.reconstruction import DEFAULT_WEIGHTS
    # before the fixture has made the files (as tests are collected), the
    # kinds of the values suffice
    files = collections.defaultdict(lambda: 'file', FIXTURE_FILES)
    files.setdefault('root', pathlib.Path('root'))
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
        'SimulatedSpikeImageDataset': dict(
            image_dir=files['images'], num_samples=2, crop_size=(8, 8),
            num_steps=5, max_side=32, pipeline=[], lazy_init=True),
        'REDSSpikeDataset': dict(pipeline=[], lazy_init=True),
        'SpikeCityscapesDataset': dict(pipeline=[], lazy_init=True),
        'SpikeReconstructor': dict(num_steps=9, channels=8, num_blocks=1,
                                   mid_channels=4),
        'WGSE': dict(hidden_channels=4),
        'ExperimentSettings': dict(grid=files['clip'], data_root='data',
                                   work_dir='work', seeds=[0], epochs=1),
        'apply_exposure': dict(image=frames[0]),
        'convert_cityscapes': dict(
            root=files['cityscapes'], out_dir=str(files['root'] / 'spikes'),
            settings=ConversionSettings(height=8, width=16, num_steps=3,
                                        frames_around=0),
            splits=('train',), progress=False),
        'time_calls': dict(fn=lambda: None, device=torch.device('cpu'),
                           repeat=1, warmup=0),
        'wavedec': dict(data=torch.zeros(2, 16), wavelet='haar'),
        'waverec': dict(coeffs=[torch.zeros(2, 8)] * 2, wavelet='haar'),
        'tfp': dict(spikes=np.zeros((3, 4, 5))),
        'tfi': dict(spikes=np.zeros((3, 4, 5))),
        'export_training_images': dict(out_dir=str(files['root'] / 'images'),
                                       sources=('matplotlib',)),
        'score_recording': dict(path=files['clip'], methods=['tfp'],
                                num_steps=5),
        'ssim': dict(pred=np.full((12, 12), 0.5), gt=np.full((12, 12), 0.5)),
        'psnr': dict(pred=np.full((4, 4), 0.5), gt=np.full((4, 4), 0.5)),
        'entropy_2d': dict(image=np.full((4, 4), 0.5)),
        'walk_recording': dict(
            path=files['clip'], video=str(files['root'] / 'walk.gif'),
            model=lambda spikes: spikes.mean(1),
            render=lambda window, rate: np.zeros((4, 6), np.uint8),
            length=3, stride=2, progress=False),
        # a stand-in the export refuses once the other arguments pass
        'export_onnx': dict(graph=None, path=str(files['root'] / 'model.onnx'),
                            num_steps=2, height=4, width=4),
        'measure_deployment': dict(name='x', config=files['missing'],
                                   cfg_options=None, shape=(2, 4, 4)),
        'load_grid': dict(path=files['missing']),
        'read_report': dict(path=files['missing']),
        'read_scene_file': dict(path=files['missing']),
        'export_weights': dict(checkpoint=DEFAULT_WEIGHTS,
                               out=str(files['root'] / 'weights.pth')),
    }.get(entry, {})


def _valid_values(name):
    """The valid value of every parameter of ``name``: the test's, else
    the default."""
    parameters = inspect.signature(ENTRY_POINTS[name]).parameters
    given = _required(name)
    return {p: given.get(p, parameter.default)
            for p, parameter in parameters.items()
            if parameter.kind not in (parameter.VAR_KEYWORD,
                                      parameter.VAR_POSITIONAL)}


_PLAIN = (type(None), bool, int, float, str, os.PathLike)


def _fuzzed(name):
    """The parameters of entry point ``name`` that take plain values."""
    parameters = inspect.signature(ENTRY_POINTS[name]).parameters
    fuzzed = []
    for parameter, value in _valid_values(name).items():
        annotation = parameters[parameter].annotation
        text = '' if annotation is inspect.Parameter.empty else (
            annotation if isinstance(annotation, str) else repr(annotation))
        plain = isinstance(value, _PLAIN) or (
            isinstance(value, (list, tuple)) and
            all(isinstance(v, _PLAIN) for v in value))
        if plain and not NOT_PLAIN.search(text) and \
                parameter not in PASSED_THROUGH.get(name, ()):
            fuzzed.append(parameter)
    return fuzzed


CALLED = [name for name in ENTRY_POINTS if name not in NOT_CALLED]
ENTRIES = [pytest.param(name, parameter, id=f'{name}.{parameter}')
           for name in CALLED for parameter in _fuzzed(name)]


def test_the_public_entry_points_are_found():
    """The API's entry points, found without reading any check, each
    called here or listed with the reason it is not, and called with a
    valid value of every parameter it has no default for."""
    assert {
        'WGSE', 'TFP', 'TFI', 'TemporalMeanFilter', 'SpatialMeanFilter',
        'SpikeSegDataPreProcessor', 'LoadSpikeFromFile', 'SpikeRandomCrop',
        'SpikeRandomFlip', 'SimulateSpikes', 'LoadSpikeImagePair',
        'PackReconstructionInputs', 'SimulatedSpikeImageDataset',
        'REDSSpikeDataset', 'SpikeReconstructor', 'SpikeCityscapesDataset',
        'SpikeVisualizationHook', 'ReconstructionMetric', 'load_spikes',
        'spike_shape', 'save_spikes', 'simulate_spikes',
        'make_synthetic_dataset', 'ConversionSettings', 'convert_cityscapes',
        'apply_exposure', 'time_calls', 'wavedec', 'waverec', 'tfp', 'tfi',
        'ssim', 'export_training_images', 'ExperimentSettings',
        'score_recording', 'walk_recording', 'export_onnx',
        'load_reconstructor', 'measure_deployment',
    } <= set(CALLED)
    assert set(NOT_CALLED) <= set(ENTRY_POINTS), (
        f'not entry points (any more): '
        f'{sorted(set(NOT_CALLED) - set(ENTRY_POINTS))}')
    for name in CALLED:
        parameters = inspect.signature(ENTRY_POINTS[name]).parameters
        required = {n for n, p in parameters.items()
                    if p.default is p.empty and
                    p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)}
        assert required <= set(_required(name)), (
            f'{name}: give the test valid values of {sorted(required)}, or '
            f'list it in NOT_CALLED with the reason')
    assert len(ENTRIES) > 150


def _never_valid(value) -> bool:
    """A value no plain parameter takes."""
    if isinstance(value, float) and not math.isfinite(value):
        return True
    return isinstance(value, (complex, bytes)) or type(value) is object


def _bad_values(valid):
    """What a careless or hostile caller passes (mostly wrong file kinds
    where the valid value is a string, a path)."""
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
    if isinstance(valid, str):
        return st.one_of(files, numbers, others)
    return st.one_of(numbers, others, files)


@pytest.fixture(scope='module')
def visualizer():
    """The visualizer instance a hook's constructor looks up, as a
    runner makes it before building its hooks."""
    from mmengine.visualization import Visualizer
    return Visualizer.get_instance('argument_fuzz')


@pytest.mark.parametrize('name, parameter', ENTRIES)
def test_bad_arguments(name, parameter, single_thread, monkeypatch,
                       bounded, visualizer):
    # relative paths drawn for outputs land in the fixture folder
    monkeypatch.chdir(FIXTURE_FILES['root'])
    call = ENTRY_POINTS[name]
    valid = _valid_values(name)
    given_files = [v for v in _required(name).values() if isinstance(v, str)]

    @settings(max_examples=6, deadline=None, database=None,
              derandomize=True, suppress_health_check=list(HealthCheck))
    @given(value=_bad_values(valid[parameter]))
    def check(value):
        # 'missing' stays missing: an example that fuzzed an output with it
        # rightly created it, and a later input would find a file there
        _remove(FIXTURE_FILES['missing'])
        kwargs = dict(_required(name), **{parameter: value})
        try:
            with bounded(TIME_BOUND_S, MEMORY_BOUND):
                call(**kwargs)
        except ArgumentError as err:
            # the parameter named; or one the test gave a stand-in for
            # (a missing file), where the value passed its check
            assert err.entry == name, err
            assert parameter in err.argument or \
                err.argument in _required(name), err
        except (WgseError, ValueError, TypeError, OSError) as err:
            # the parameter or the file named; or a file the test gave,
            # where the value passed its check and the call went on
            message = str(err)
            named = [parameter] + given_files + (
                [value] if isinstance(value, str) and value else [])
            assert any(word in message for word in named), (
                f'{name}({parameter}={value!r}): '
                f'{type(err).__name__}: {message}')
            raised_in = _traceback_files(err)[-1]
            assert raised_in.startswith(PACKAGE_DIRS), (
                f'{name}({parameter}={value!r}) raised deep in '
                f'{raised_in}: {type(err).__name__}: {message}')
        else:
            assert not _never_valid(value), (
                f'{name}({parameter}={value!r}) was accepted')

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
    and parts, so that a refusal in a spawned worker (the benchmarks')
    reaches the parent as it was raised."""
    import pickle
    error = ArgumentError('WGSE', 'level', 'an integer >= 1', 10**6)
    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is ArgumentError and str(copy) == str(error)
    assert (copy.entry, copy.argument, copy.expected) == (
        'WGSE', 'level', 'an integer >= 1')
