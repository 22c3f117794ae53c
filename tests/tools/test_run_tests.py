"""``tools/run_tests.sh`` runs what it is given: a test path and ``-k`` only
those tests, ``--lf`` the last run's failures from pytest's cache, and the
compiles for GPU targets only where ``--gpu-targets`` asks for them.

Run in the checkout's own environment of this suite's stack (the README's
install mode, as CI runs the suite); elsewhere the test skips, since the
script would set that environment up first."""
import json
import os
import os.path as osp
import re
import subprocess
import sys

import pytest

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
#: the checkout's environment of each stack (tools/setup_env.sh)
VENVS = {'.venv': 'openmmlab', '.venv-onedl': 'onedl'}
#: a test of a small module of several
NODE = 'tests/test_repo_rules.py::test_the_plugin_part_is_held_short'


@pytest.fixture
def env():
    """This process's environment for the script, with this suite's stack
    and without the variables of this pytest run; a skip outside the
    checkout's environments."""
    stacks = [stack for venv, stack in VENVS.items()
              if osp.realpath(osp.join(ROOT, venv)) ==
              osp.realpath(sys.prefix)]
    if not stacks:
        pytest.skip(f'this suite runs in {sys.prefix}, not in the '
                    f'checkout\'s {" or ".join(VENVS)}')
    return dict({name: value for name, value in os.environ.items()
                 if not name.startswith('PYTEST_')}, STACK=stacks[0])


@pytest.mark.parametrize('args, workers', [
    ((), True), (('-p', 'no:randomly', '-o', 'console_output_style=count',
                  '-W', 'error', '--durations', '5'), True),
    (('tests/core',), False), (('-k', 'gradcheck'), False),
    (('-p', 'no:randomly', '--lf'), False)])
def test_workers_for_the_whole_suite_one_process_for_a_selection(
        env, args, workers):
    """The pytest command the script starts, read from its trace
    (``bash -x``); ``--version`` makes that pytest stop at once."""
    proc = subprocess.run(['bash', '-x', 'tools/run_tests.sh', *args,
                           '--version'], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    started, = [line for line in proc.stderr.splitlines()
                if line.startswith('+ exec ')]
    assert started.endswith(' '.join(('-m pytest',
                                      *(('-n', 'auto', '--dist', 'worksteal')
                                        if workers else ('-n', '0')),
                                      *args, '--version'))), started


@pytest.mark.long(20)
def test_a_path_with_k_and_lf_run_only_those(env, tmp_path):
    # the inner run's own cache and temporary folders, not this run's
    cache = tmp_path / 'cache'

    def run(*args):
        proc = subprocess.run(
            ['bash', 'tools/run_tests.sh', *args,
             '-o', f'cache_dir={cache}', f'--basetemp={tmp_path / "base"}'],
            cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
        return proc.stdout

    out = run(NODE.split('::')[0], '-k', 'plugin_part')
    assert re.search(r'= 1 passed, [1-9]\d* deselected\b', out), out[-2000:]
    # the cache as a run in which that test failed left it
    (cache / 'v' / 'cache').mkdir(parents=True, exist_ok=True)
    (cache / 'v' / 'cache' / 'lastfailed').write_text(
        json.dumps({NODE: True}))
    out = run('--lf')
    assert 'run-last-failure: rerun previous 1 failure' in out, out[-2000:]
    assert re.search(r'= 1 passed\b', out), out[-2000:]
    assert json.loads((cache / 'v' / 'cache' / 'lastfailed').read_text()) \
        == {}


def test_the_compiles_for_gpu_targets_skip_unless_asked(env, tmp_path):
    """The suite skips the tests marked ``gpu_targets``, naming the command
    that runs them; ``--gpu-targets -m gpu_targets`` picks exactly those,
    and .ci/run gives that command a step of its own."""
    path = 'tests/bench/test_triton_resources.py'
    options = ['-o', f'cache_dir={tmp_path / "cache"}',
               f'--basetemp={tmp_path / "base"}']

    def run(*args):
        proc = subprocess.run(['bash', 'tools/run_tests.sh', path, *args,
                               *options], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
        return proc.stdout

    out = run('-k', 'every_launchable or by_hand', '-rs')
    assert re.search(r'= \d+ passed, 1 skipped\b', out), out[-2000:]
    assert 'bash tools/run_tests.sh --gpu-targets -m gpu_targets' in out
    out = run('--gpu-targets', '-m', 'gpu_targets', '--collect-only', '-q')
    picked = {line.split('::')[1].split('[')[0]
              for line in out.splitlines() if line.startswith(path)}
    assert 'test_every_launchable_variant_compiles_for_every_target' in picked
    assert not {name for name in picked if 'by_hand' in name}
    with open(osp.join(ROOT, '.ci', 'run'), encoding='utf-8') as f:
        assert 'bash tools/run_tests.sh -q --gpu-targets -m gpu_targets ' \
            '|| status=1' in f.read().splitlines()
