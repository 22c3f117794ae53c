"""SpikeRunner loads checkpoints as data: config text in one is never
executed; a training owns its work dir."""
import copy
import errno
import os
import os.path as osp
import sys
import threading
import time

import pytest
import torch

import wgse_mmseg
from wgse_mmseg.fileio.input_guard import OutputFolderError
from wgse_mmseg.fileio.locks import own_folder
from wgse_mmseg.utils.checkpoint import CheckpointError
from wgse_mmseg.utils.config import build_runner, load_config

wgse_mmseg.register_all_modules()

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


@pytest.fixture(scope='module')
def runner(tmp_path_factory):
    """One runner for the module: neither test changes it (the refused
    resume stops before loading; the other loads the model's own state)."""
    cfg = load_config(osp.join(ROOT, 'configs', 'reconstruction',
                               'wgse_resnet_cpu.py'),
                      {'model.channels': 4, 'model.mid_channels': 4})
    cfg.work_dir = str(tmp_path_factory.mktemp('work'))
    runner = build_runner(cfg)
    assert type(runner).__name__ == 'SpikeRunner'
    return runner


def test_resume_executes_no_config_text_from_a_checkpoint(runner, tmp_path):
    """mmengine's ``Runner.resume`` executes ``meta['config']`` with
    ``Config.fromstring``; SpikeRunner refuses the checkpoint first, naming
    the file and the key, and nothing is written."""
    marker = tmp_path / 'pwned'
    path = str(tmp_path / 'downloaded.pth')
    torch.save(dict(state_dict=runner.model.state_dict(), meta=dict(
        epoch=0, iter=1,
        config=f"open(r'{marker}', 'w').write('ran')\ngpu_ids = [0]\n")),
        path)
    with pytest.raises(CheckpointError,
                       match=r"downloaded.pth: meta\['config'\]"):
        runner.resume(path)
    assert not marker.exists()


def test_a_checkpoint_with_its_config_as_data_still_loads(runner, tmp_path):
    """What mmengine writes (``meta['cfg']`` text) is not refused."""
    path = str(tmp_path / 'iter_1.pth')
    torch.save(dict(state_dict=runner.model.state_dict(),
                    meta=dict(cfg=runner.cfg.pretty_text, iter=1)), path)
    checkpoint = runner.load_checkpoint(path, strict=True)
    assert checkpoint['meta']['iter'] == 1


class _OpensAFile:
    """Pickles as ``open(path, 'w')``: code run by a full unpickling."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return open, (self.path, 'w')


@pytest.mark.parametrize('how', ['load_from', 'resume'])
def test_a_checkpoint_that_pickles_code_is_refused(runner, tmp_path, how):
    """As ``load_from`` or to resume, on either stack: refused by the
    weights-only loader (the fork's mmengine would retry in full), an error
    naming the file, and the pickled call never runs."""
    marker = tmp_path / 'ran'
    path = str(tmp_path / 'downloaded.pth')
    torch.save(dict(state_dict=runner.model.state_dict(),
                    meta=dict(epoch=0, iter=1, x=_OpensAFile(marker))), path)
    with pytest.raises(CheckpointError, match=r'downloaded.pth: refused'):
        if how == 'resume':
            runner.resume(path)
        else:
            runner.load_checkpoint(path)
    assert not marker.exists()


#: The training's samples are loaded in the test process: a loader worker
#: would be a fork of it, and a fork of a process with other threads (the
#: test runner's) can deadlock or crash in the child.
IN_PROCESS_LOADING = {'train_dataloader.num_workers': 0,
                      'train_dataloader.persistent_workers': False}


def _training_runner(work_dir, **settings):
    """The CPU reconstruction config's runner (synthetic data made on the
    fly) for one iteration, nothing validated."""
    cfg = load_config(osp.join(ROOT, 'configs', 'reconstruction',
                               'wgse_resnet_cpu.py'),
                      {'model.channels': 4, 'model.mid_channels': 4,
                       'train_cfg.max_iters': 1, 'train_cfg.val_interval': 2,
                       'default_hooks.checkpoint.interval': 2,
                       **IN_PROCESS_LOADING, **settings})
    cfg.work_dir = str(work_dir)
    return build_runner(cfg)


def test_a_second_training_into_a_work_dir_is_refused_naming_the_first(
        tmp_path):
    """Another training owns the work dir (here: this process, through
    the same lock): this one stops before it writes its config or a
    checkpoint there, naming the owner; the owner's lock stays."""
    work = tmp_path / 'work'
    runner = _training_runner(work)
    with own_folder(str(work), job='train', claim=False):
        with pytest.raises(OutputFolderError,
                           match=rf'work: another process is writing this '
                           rf'output \(process {os.getpid()} on '):
            runner.train()
        assert (work / '.lock-train').is_file()
    assert not list(work.glob('*.py')) and not list(work.glob('*.pth'))
    assert not (work / '.lock-train').exists()


def test_the_train_tool_stops_naming_the_owner_or_waits_with_wait(
        load_tool, tmp_path, monkeypatch):
    """``tools/train.py`` into an owned work dir: its error line names the
    work dir and the owner; with ``--wait`` it trains once it is free."""
    work = tmp_path / 'work'
    argv = ['train.py', osp.join(ROOT, 'configs', 'reconstruction',
                                 'wgse_resnet_cpu.py'),
            '--work-dir', str(work), '--cfg-options', 'model.channels=4',
            'model.mid_channels=4', 'train_cfg.max_iters=1',
            'train_cfg.val_interval=2', 'default_hooks.checkpoint.interval=2',
            *(f'{key}={value}' for key, value in IN_PROCESS_LOADING.items())]
    train = load_tool('tools/train.py')
    monkeypatch.setattr(sys, 'argv', argv)
    with own_folder(str(work), job='train'), \
            pytest.raises(SystemExit) as stop:
        train.main()
    assert str(stop.value.code).startswith(
        f'train.py: error: {work}: another process is writing this output')
    monkeypatch.setattr(sys, 'argv', argv + ['--wait'])
    owner = own_folder(str(work), job='train', claim=False)
    owner.__enter__()
    threading.Timer(1.0, owner.__exit__, (None, None, None)).start()
    start = time.monotonic()
    train.main()  # waits, then owns the work dir and trains its iteration
    assert time.monotonic() - start >= 1.0
    assert list(work.glob('*.py')) and (work / 'last_checkpoint').is_file()
    assert not (work / '.lock-train').exists()  # let go at the end


def test_the_train_tool_refuses_amp_without_a_gpu(load_tool, monkeypatch):
    """``--amp`` on a machine without a GPU: one line naming the option,
    before anything is built (mmengine's AmpOptimWrapper would stop with
    an AssertionError from deep inside the runner)."""
    monkeypatch.setattr(sys, 'argv', [
        'train.py', osp.join(ROOT, 'configs', 'pspnet_wgse.py'), '--amp'])
    monkeypatch.setattr(torch.cuda, 'is_available', lambda: False)
    with pytest.raises(SystemExit) as stop:
        load_tool('tools/train.py').main()
    assert str(stop.value.code).startswith(
        'train.py: error: --amp: mixed-precision training needs a GPU')


def test_a_training_writes_no_file_of_the_users_through_a_link(tmp_path):
    """``last_checkpoint`` (written in place by mmengine) and the save's
    temporary, put in the work dir as a hard link and a symbolic link to
    the user's files: the training writes its own files, the user's keep
    their content."""
    work = tmp_path / 'work'
    work.mkdir()
    notes, thesis = tmp_path / 'notes.txt', tmp_path / 'thesis.txt'
    notes.write_text('notes')
    thesis.write_text('thesis')
    os.link(notes, work / 'last_checkpoint')
    stale = work / '.tmp-iter_1.pth.a1b2c3.pth'  # a killed save's name
    stale.symlink_to(thesis)
    _training_runner(work, **{'default_hooks.checkpoint.interval': 1}).train()
    assert notes.read_text() == 'notes' and thesis.read_text() == 'thesis'
    assert (work / 'last_checkpoint').read_text().endswith('iter_1.pth')
    assert (work / 'iter_1.pth').is_file()
    assert not [n for n in os.listdir(work) if n.startswith('.tmp-')]


@pytest.mark.parametrize('error', [errno.ENOSPC, errno.EFBIG, errno.EACCES])
def test_a_failed_checkpoint_save_leaves_no_temporary_and_names_the_file(
        tmp_path, monkeypatch, error):
    """mmengine's write of a checkpoint fails half-way (a full disk, a
    file-size limit, a permission): the error names the checkpoint's path,
    keeps its errno (so its ``OSError`` subclass), and the half-written
    temporary is gone; the previous checkpoint and ``last_checkpoint``
    are as they were."""
    from mmengine.fileio.backends import local_backend
    work = tmp_path / 'work'
    work.mkdir()
    (work / 'last_checkpoint').write_text('earlier')

    def failing_put(self, obj, filepath):
        with open(filepath, 'wb') as f:
            f.write(obj[:100])
        raise OSError(error, os.strerror(error))

    monkeypatch.setattr(local_backend.LocalBackend, 'put', failing_put)
    runner = _training_runner(work, **{'default_hooks.checkpoint.interval': 1})
    with pytest.raises(OSError) as info:
        runner.train()
    assert info.value.errno == error
    assert type(info.value) is type(OSError(error, 'x'))
    assert str(work / 'iter_1.pth') in str(info.value)
    assert os.strerror(error) in str(info.value)
    assert not (work / 'iter_1.pth').exists()
    assert not [n for n in os.listdir(work) if n.startswith('.tmp-')]
    assert (work / 'last_checkpoint').read_text() == 'earlier'


def test_the_config_text_is_mmengines_formatted_once_per_content(
        runner, monkeypatch):
    """The runner's ``pretty_text`` is mmengine's own text; yapf formats it
    once however often a run asks, and again once the config changes."""
    import yapf.yapflib.yapf_api as yapf_api
    from mmengine.config import Config
    import mmengine.config.config as config_module
    plain = Config(runner.cfg.to_dict())
    expected = plain.pretty_text
    formatted = []
    original = yapf_api.FormatCode

    def counted(*args, **kwargs):
        formatted.append(args[0])
        return original(*args, **kwargs)

    monkeypatch.setattr(yapf_api, 'FormatCode', counted)
    if hasattr(config_module, 'FormatCode'):  # bound at import (0.10.7)
        monkeypatch.setattr(config_module, 'FormatCode', counted)
    cfg = copy.deepcopy(runner.cfg)  # the fixture is shared
    assert type(cfg) is type(runner.cfg) is not Config
    cfg.__dict__.pop('_formatted', None)
    assert [cfg.pretty_text for _ in range(3)] == [expected] * 3
    assert len(formatted) == 1
    cfg.randomness = dict(seed=123)
    assert 'seed=123' in cfg.pretty_text and len(formatted) == 2
    assert cfg.pretty_text == Config(cfg.to_dict()).pretty_text


def test_the_runs_log_leaves_out_what_no_user_can_act_on():
    import logging
    from wgse_mmseg.engine.runner import _Unactionable

    def record(message):
        return logging.LogRecord('mmengine', logging.WARNING, __file__, 1,
                                 message, None, None)
    unactionable = _Unactionable()
    assert not unactionable.filter(record(
        '"FileClient" will be deprecated in future. Please use io functions'))
    assert not unactionable.filter(record(
        'The prefix is not set in metric class IoUMetric.'))
    assert unactionable.filter(record('crop_size=(16, 32) is below ...'))
