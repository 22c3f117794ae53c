"""The ONNX export tool's output file (tools/deployment/pytorch2onnx.py):
a second export to the same file is refused naming the first. That an
export failing its own check leaves no file (one already there kept as it
was) and the interface checks are tested in
tests/apis/test_onnx_export.py."""
import os
import os.path as osp

import pytest
import torch

import wgse_mmseg
from mmengine.registry import init_default_scope
from mmseg.registry import MODELS
from wgse_mmseg.fileio.locks import own_folder
from wgse_mmseg.utils.config import load_config

wgse_mmseg.register_all_modules()  # before mmseg builds anything

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
CONFIG = osp.join(ROOT, 'configs', 'segformer_b0_raw.py')
T, H, W = 9, 32, 64


@pytest.fixture
def checkpoint(tmp_path):
    cfg = load_config(CONFIG, dict(num_steps=T))
    init_default_scope(cfg.get('default_scope', 'mmseg'))
    torch.manual_seed(0)
    path = str(tmp_path / 'model.pth')
    torch.save(dict(state_dict=MODELS.build(cfg.model).state_dict()), path)
    return path


def _arguments(checkpoint, out):
    return [CONFIG, checkpoint, '--shape', str(T), str(H), str(W), '--out',
            out, '--cfg-options', f'num_steps={T}']


def test_a_second_export_to_one_file_is_refused(tmp_path, checkpoint,
                                                load_tool):
    tool = load_tool('tools/deployment/pytorch2onnx.py')
    out = str(tmp_path / 'm.onnx')
    with own_folder(str(tmp_path), 'm.onnx', claim=False):
        with pytest.raises(SystemExit, match=r'another process is writing '
                           rf'this output \(process {os.getpid()} on host'):
            tool.main(_arguments(checkpoint, out))
    assert sorted(os.listdir(tmp_path)) == ['model.pth']
