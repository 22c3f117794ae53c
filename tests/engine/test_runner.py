"""SpikeRunner loads checkpoints as data: config text in one is never
executed."""
import os.path as osp

import pytest
import torch

import wgse_mmseg
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
