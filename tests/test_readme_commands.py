"""Every command the README and the pages its sections moved to give works
as written, in the README's install mode (``tools/setup_env.sh``'s editable
install in ``.venv``).

The pages are :data:`PAGES`: the README and the docs pages that hold what it
held before it was cut to the OpenMMLab projects' form (install, user guide,
security, troubleshooting, known limits). Each command of their ``bash`` blocks
(continuation lines joined, comments and ``[optional]`` parts left out) must
have an entry in :data:`HOW`, keyed by its exact text, saying how it is
checked:

* ``RUN``: run here, literally, by :func:`test_readme_command_runs`;
* a test's node id: that test runs the same tool on the same config with
  only size-reducing options added (tiny data, fewer epochs);
* ``CI``: ``.ci/run`` runs it on every submission;
* :class:`NotHere` with the reason (GPUs, a cluster, a 30-minute compile)
  and the test that runs its CPU counterpart.

A command added or changed in the README without an entry here, an entry
whose command is gone, a repository path a command names that does not
exist, or a node id that names no test fails. The pages' Python examples
run as written.
"""
import ast
import os
import os.path as osp
import re
import shlex
import subprocess
import sys
from typing import NamedTuple

import numpy as np
import pytest

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: the pages whose commands are checked here, each path from the root
PAGES = ('README.md', 'docs/install.md', 'docs/user_guide.md',
         'docs/security.md', 'docs/troubleshooting.md', 'docs/known_limits.md')
BIN = osp.dirname(sys.executable)
SHARED = osp.normpath(osp.join(ROOT, '..', 'shared'))

RUN = 'run here'
CI = ('.ci/run runs tools/lint.sh and tools/run_tests.sh, each of which '
      'runs tools/setup_env.sh first')


class NotHere(NamedTuple):
    """A command that cannot run on a CI machine, why, and the test that runs
    its CPU counterpart."""
    why: str
    counterpart: str


TRAIN_TESTS = 'tests/tools/test_mim_end_to_end.py::' \
    'test_mim_in_the_readme_install_mode'
RUN_TESTS_TEST = 'tests/tools/test_run_tests.py::' \
    'test_a_path_with_k_and_lf_run_only_those'
DIST_TEST = 'tests/tools/test_distributed_training.py::' \
    'test_dist_train_and_dist_test_scripts_on_cpu'

#: every README command, exactly as :func:`readme_commands` gives it
HOW = {
    'bash tools/quickstart.sh': RUN,
    'bash tools/run_tests.sh': CI,
    'bash tools/setup_env.sh': CI,
    'STACK=onedl bash tools/setup_env.sh': CI,
    'STACK=onedl bash tools/run_tests.sh': CI,
    'bash tools/run_tests.sh tests/core/test_wavelets.py -k gradcheck':
        RUN_TESTS_TEST,
    'bash tools/run_tests.sh --lf': RUN_TESTS_TEST,
    'bash tools/run_tests.sh --gpu-targets -m gpu_targets': CI,
    'bash tools/lint.sh': CI,
    'MMCV=full bash tools/setup_env.sh': NotHere(
        'compiles mmcv 2.1.0 for about 30 minutes and replaces mmcv-lite in '
        'the environment the other tests use', 'tests/compat/test_compat.py::'
        'test_full_mmcv_is_left_alone'),
    'source .venv/bin/activate': RUN,
    'source .venv-onedl/bin/activate': RUN,
    'CONFIG=configs/pspnet_wgse.py': RUN,
    'python tools/train.py $CONFIG': TRAIN_TESTS,
    'mim train wgse_mmseg $CONFIG': TRAIN_TESTS,
    'python tools/train.py $CONFIG --resume': TRAIN_TESTS,
    'python tools/test.py $CONFIG work_dirs/pspnet_wgse/epoch_100.pth':
        TRAIN_TESTS,
    'python tools/test.py $CONFIG CKPT --show-dir vis/ --tta': TRAIN_TESTS,
    'python tools/deployment/pytorch2onnx.py configs/segformer_b0_wgse.py '
    'work_dirs/segformer_b0_wgse/epoch_100.pth --shape 129 256 512':
        'tests/apis/test_onnx_export.py::'
        'test_the_tool_exports_a_checkpoint_and_checks_it',
    'python tools/analysis_tools/benchmark_deployment.py '
    'configs/experiments/grid_cpu.py --only segformer_b0_raw '
    'segformer_b0_tfp segformer_b0_wgse1d pspnet_raw pspnet_tfp '
    'pspnet_wgse1d --threads 1 --out docs/deployment_cpu.json': NotHere(
        'exports and times six full-size models for about 20 minutes on 2 '
        'cores', 'tests/apis/test_onnx_export.py::'
        'test_measure_deployment_times_both_backends'),
    'python tools/demo.py clip_spike.spk $CONFIG CKPT --out-file seg.png':
        'tests/tools/test_demo_and_example.py::test_demo_writes_overlay',
    'python tools/demo.py recording.dat $CONFIG CKPT --stride 100 '
    '--out-file walk.mp4': 'tests/tools/test_demo_and_example.py::'
    'test_demo_walk_segments_each_window_as_the_one_window_demo',
    'bash tools/dist_train.sh configs/pspnet_wgse.py 8 --cfg-options '
    'data_root=/data/spikes': NotHere('8 GPUs', DIST_TEST),
    'bash tools/dist_test.sh configs/pspnet_wgse.py '
    'work_dirs/pspnet_wgse/epoch_100.pth 8': NotHere('8 GPUs', DIST_TEST),
    'NNODES=2 NODE_RANK=0 MASTER_ADDR=host0 bash tools/dist_train.sh '
    'configs/pspnet_wgse.py 8': NotHere('two hosts with 8 GPUs', DIST_TEST),
    'bash tools/slurm_train.sh PARTITION JOB_NAME configs/pspnet_wgse.py 16':
        NotHere('a Slurm cluster', DIST_TEST),
    'mim train wgse_mmseg configs/pspnet_wgse.py --gpus 8 --launcher pytorch':
        NotHere('8 GPUs', TRAIN_TESTS),
    'python tools/train.py configs/pspnet_wgse.py --cfg-options num_steps=41 '
    'data_root=/data/spikes crop_size=128,256':
        TRAIN_TESTS,
    'python tools/dataset_converters/spike_cityscapes.py data/cityscapes '
    'data/spike_cityscapes --nproc 2':
        'tests/data_generation/test_cityscapes_conversion.py::'
        'test_cli_in_parallel_then_resume',
    'python tools/analysis_tools/benchmark.py configs/pspnet_wgse.py '
    'configs/pspnet_raw.py configs/segformer_b0_wgse.py '
    'configs/segformer_b0_raw.py --crop 64 128 --repeat 3 --cfg-options '
    'num_steps=41': 'tests/bench/test_segmentation.py::'
    'test_cli_prints_the_table_and_writes_json',
    'python tools/analysis_tools/run_experiments.py '
    'configs/experiments/grid_cpu.py --data-root '
    'data/synthetic_spike_cityscapes --work-dir work_dirs/grid_cpu '
    '--report-dir docs': 'tests/bench/test_experiments.py::'
    'test_tiny_grid_end_to_end_and_resume',
    'python tools/analysis_tools/benchmark.py configs/pspnet_wgse.py '
    'configs/pspnet_raw.py configs/segformer_b0_wgse.py '
    'configs/segformer_b0_raw.py --crop 64 128 --repeat 3 --cfg-options '
    'num_steps=41 --out docs/configs_benchmark_cpu.json':
        'tests/bench/test_segmentation.py::'
        'test_cli_prints_the_table_and_writes_json',
    'python tools/misc/reconstruct.py ../shared/data/reds_sample/spike/'
    '203_part2_key_id151.dat --height 250 --width 400 --frames 100,150,200 '
    '--out recon/': RUN,
    'python tools/misc/reconstruct.py clip.npy --layout THW --out recon/ '
    '--method tfp': RUN,
    'python tools/misc/reconstruct.py ../shared/data/reds_sample/spike/'
    '203_part2_key_id151.dat --height 250 --width 400 --stride 30 --fps 4 '
    '--out walk.gif': RUN,
    'python -m wgse_bench.reconstruction '
    '../shared/data/reds_sample': RUN,
    'python -m wgse_bench.reconstruction '
    '../shared/data/real/uhsr_helicopter.npz --frames 50,100,150': RUN,
    'bash tools/train_reconstruction.sh':
        'tests/tools/test_train_reconstruction.py::'
        'test_the_recipe_runs_start_to_finish',
}

#: what a command run here must print (a regular expression)
PRINTS = {
    # trained with the fixed seed (the README's metrics rerun), evaluated
    'bash tools/quickstart.sh': r'(?s)\n +seed: 0\n.*mIoU: [\d.]+',
    'python tools/misc/reconstruct.py ../shared/data/reds_sample/spike/'
    '203_part2_key_id151.dat --height 250 --width 400 --frames 100,150,200 '
    '--out recon/': r'recon/203_part2_key_id151_200\.png\texposure_gain=1\t'
                    r'.*left as it is',
    'python tools/misc/reconstruct.py clip.npy --layout THW --out recon/ '
    '--method tfp': r'recon/clip_20\.png',
    'python tools/misc/reconstruct.py ../shared/data/reds_sample/spike/'
    '203_part2_key_id151.dat --height 250 --width 400 --stride 30 --fps 4 '
    '--out walk.gif': r'9 windows of 41 readouts centred on readouts '
                      r'30\.\.270 every 30 .* at the start 0, at the end 300'
                      r'\nwalk\.gif\nwalk\.csv',
    'python -m wgse_bench.reconstruction '
    '../shared/data/reds_sample': r'\| WGSE \| \d\d\.\d\d \|',
    'python -m wgse_bench.reconstruction '
    '../shared/data/real/uhsr_helicopter.npz --frames 50,100,150':
        r'\| WGSE +\| +\d+\.\d+ \|',
}


def _suite_stack() -> str:
    """The stack (``STACK=`` of tools/setup_env.sh) this suite runs on."""
    from wgse_mmseg.openmmlab_stack import installed_stacks
    (stack,) = installed_stacks()
    return stack


#: environment a command run here gets: the quickstart's documented
#: variables, for its shortest schedule on a third of its data into a
#: temporary directory, on the stack of this suite (in that stack's virtual
#: environment of the checkout)
ENVIRONMENT = {
    'bash tools/quickstart.sh': lambda tmp: dict(
        EPOCHS='2', NUM_TRAIN='16', NUM_VAL='4', DATA=str(tmp / 'data'),
        WORK=str(tmp / 'work'), STACK=_suite_stack()),
}
#: ``source`` commands, each for one stack's virtual environment: run in
#: the stage of CI whose suite runs in it
ACTIVATES = {'source .venv/bin/activate': '.venv',
             'source .venv-onedl/bin/activate': '.venv-onedl'}

#: what a command run here reads, made for it in its working directory
INPUTS = {
    'clip.npy': lambda path: np.save(path, (np.random.default_rng(0).random(
        (41, 16, 24)) < 0.3).astype(np.uint8)),
}


def _blocks(language):
    blocks = []
    for page in PAGES:
        text = open(osp.join(ROOT, page), encoding='utf-8').read()
        blocks += re.findall(rf'^```{language}\n(.*?)^```', text, re.S | re.M)
    return blocks


def readme_commands():
    """The pages' shell commands, each once: continuation lines joined,
    comments and ``[optional]`` parts left out, whitespace collapsed."""
    commands = []
    for block in _blocks('bash'):
        for line in block.replace('\\\n', ' ').splitlines():
            line = re.sub(r'\s#.*$', '', line)  # comments
            line = re.sub(r'\[[^\]]*\]', '', line)  # [optional] parts
            line = ' '.join(line.split())
            if line and line not in commands:
                commands.append(line)
    return commands


def test_every_readme_command_is_checked():
    commands = readme_commands()
    assert set(LONG) <= set(RUN_HERE), set(LONG) - set(RUN_HERE)
    unchecked = [c for c in commands if c not in HOW]
    stale = [c for c in HOW if c not in commands]
    assert not unchecked, ('README commands without an entry in HOW (add '
                           'one):\n' + '\n'.join(unchecked))
    assert not stale, ('HOW entries the README no longer gives:\n' +
                       '\n'.join(stale))


@pytest.mark.parametrize('command', readme_commands())
def test_readme_command_names_what_exists(command):
    """Every repository path a command names is there; every test it is
    checked by exists."""
    for word in shlex.split(command):
        value = word.split('=', 1)[-1]
        if re.match(r'(tools|dev|configs)/', value):
            assert osp.exists(osp.join(ROOT, value)), (command, value)
        elif value.startswith(('wgse_mmseg.', 'wgse_bench.')):
            module = osp.join(ROOT, *value.split('.'))
            assert osp.isfile(module + '.py'), (command, value)
    how = HOW.get(command)
    nodes = [how.counterpart] if isinstance(how, NotHere) else \
        [how] if isinstance(how, str) and '::' in how else []
    for node in nodes:
        path, name = node.split('::')
        tree = ast.parse(open(osp.join(ROOT, path), encoding='utf-8').read())
        names = {n.name for n in ast.walk(tree)
                 if isinstance(n, ast.FunctionDef)}
        assert name in names, f'{command}: no test {node}'


def _session(tmp_path):
    """A working directory like the repository root for a command run
    here: the repository's files linked in, ``../shared`` beside it, and
    the outputs (``recon/``, ``work_dirs/``) written inside it."""
    work = tmp_path / 'repo'
    work.mkdir()
    for name in os.listdir(ROOT):
        if name not in ('.git', 'work_dirs', 'data', 'recon'):
            (work / name).symlink_to(osp.join(ROOT, name))
    if osp.isdir(SHARED):
        (tmp_path / 'shared').symlink_to(SHARED)
    return work


RUN_HERE = [c for c in readme_commands() if HOW.get(c) == RUN]
#: the commands run here that take tens of seconds: ``long`` tests
LONG = {'bash tools/quickstart.sh': 100,
        'python -m wgse_bench.reconstruction '
        '../shared/data/reds_sample': 30,
        'python tools/misc/reconstruct.py ../shared/data/reds_sample/spike/'
        '203_part2_key_id151.dat --height 250 --width 400 --stride 30 --fps 4 '
        '--out walk.gif': 28,
        'python tools/misc/reconstruct.py ../shared/data/reds_sample/spike/'
        '203_part2_key_id151.dat --height 250 --width 400 --frames '
        '100,150,200 --out recon/': 17,
        'python -m wgse_bench.reconstruction '
        '../shared/data/real/uhsr_helicopter.npz --frames 50,100,150': 17}


@pytest.mark.parametrize('command', [
    pytest.param(c, marks=pytest.mark.long(LONG[c])) if c in LONG else c
    for c in RUN_HERE])
def test_readme_command_runs(command, tmp_path):
    if '../shared' in command and not osp.isdir(SHARED):
        pytest.skip(f'{SHARED} is absent (fresh clone)')
    if command in ACTIVATES and osp.realpath(
            osp.join(ROOT, ACTIVATES[command])) != osp.realpath(sys.prefix):
        pytest.skip(f'this suite runs in {sys.prefix}; CI runs the suite in '
                    f'{ACTIVATES[command]} too')
    # The quickstart sets up .venv in the checkout itself (an editable
    # install of the checkout), so it runs there; its outputs go to tmp.
    cwd = ROOT if command == 'bash tools/quickstart.sh' else \
        _session(tmp_path)
    for name, make in INPUTS.items():
        if name in shlex.split(command):
            make(osp.join(cwd, name))
    env = dict(os.environ, PATH=BIN + os.pathsep + os.environ['PATH'],
               **ENVIRONMENT.get(command, lambda tmp: {})(tmp_path))
    env.pop('TRITON_INTERPRET', None)  # the user's own shell
    # `python` finds the package afterwards, and whose environment it is
    # (found, not imported: importing it is the suite's own business)
    check = ("; python -c 'import importlib.util as u, os, sys; "
             "assert u.find_spec(\"wgse_mmseg\"), sys.prefix; "
             "print(os.path.realpath(sys.prefix))'")
    result = subprocess.run(['bash', '-c', f'set -e; {command}{check}'],
                            cwd=cwd, env=env, capture_output=True,
                            text=True, timeout=900)
    log = result.stdout + result.stderr
    assert result.returncode == 0, f'{command}:\n{log[-4000:]}'
    # the README's install mode: the .venv's python answers to `python`
    assert result.stdout.splitlines()[-1] == osp.realpath(
        osp.dirname(BIN)), log[-2000:]
    if command in PRINTS:
        assert re.search(PRINTS[command], log), f'{command}:\n{log[-3000:]}'


@pytest.mark.parametrize('block', list(dict.fromkeys(
    b for b in _blocks('python') if not b.startswith('_base_'))))
def test_readme_python_example_runs(block, tmp_path):
    """The README's Python examples run as written, in a fresh process;
    config excerpts (``_base_ = ...``) are checked by the config tests."""
    env = dict(os.environ, PATH=BIN + os.pathsep + os.environ['PATH'])
    env.pop('TRITON_INTERPRET', None)
    result = subprocess.run([sys.executable, '-c', block], cwd=tmp_path,
                            env=env, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    for expected in re.findall(r'# (torch\.Size\(\[[\d, ]+\]\))', block):
        assert expected in result.stdout, result.stdout
