"""A tool answers ``--help`` and an argument error before it imports torch,
OpenMMLab, Triton, ONNX or OpenCV, and ``import wgse_mmseg`` imports none of
them (what makes them answer at once: the figures are
``dev/benchmark_startup.py``'s, not a test's)."""
import pytest


@pytest.fixture(scope='module')
def startup(load_tool):
    return load_tool('dev/benchmark_startup.py')


def test_every_tool_answers_before_the_heavy_imports(startup):
    tools = startup.tools()
    assert 'tools/train.py' in tools and len(tools) >= 16
    assert {'dev/sweep_band_kernels.py',
            'tools/analysis_tools/run_experiments.py'} <= set(tools)
    heavy = {}
    for tool in sorted(tools):
        for argument in ('--help', '--no-such-option'):
            imported = startup.heavy_imports([tool, argument])
            if imported:
                heavy[f'{tool} {argument}'] = imported
    assert not heavy, f'imported before the arguments were read: {heavy}'


def test_the_check_sees_a_heavy_import(startup):
    """The reading of ``-X importtime`` finds what a process imports."""
    assert startup.heavy_imports(['-c', 'import cv2']) == ['cv2']
    assert startup.heavy_imports(
        ['-c', 'import wgse_mmseg.core.wgse'])[:1] == ['torch']


def test_importing_the_package_imports_nothing_heavy(startup):
    assert startup.heavy_imports(['-c', 'import wgse_mmseg']) == []
    # nor the command-line kinds the tools' parsers are built from
    assert startup.heavy_imports(
        ['-c', 'import wgse_mmseg.command_line, '
         'wgse_mmseg.apis.recording_walk, wgse_mmseg.utils.config']) == []
