"""Config text in data files (checkpoints) is read, never executed."""
import pytest
from hypothesis import given
from hypothesis import strategies as st
from mmengine.config import Config

from wgse_mmseg.utils.config_data import ConfigDataError, read_config_data


def test_reads_what_mmengine_writes():
    """A real ``pretty_text`` round-trips to the same values as mmengine's
    own (executing) parser gives."""
    cfg = Config(dict(model=dict(type='SpikeReconstructor', channels=64,
                                 enhancer=dict(type='WGSE', level=5,
                                               mode='zero'),
                                 sizes=(1, 2), scale=-0.5, flag=None),
                      optim=[dict(lr=1e-3, betas=(0.9, 0.999))]))
    values = read_config_data(cfg.pretty_text, 'test')
    expected = Config.fromstring(cfg.pretty_text, '.py')
    assert values['model'] == expected.model.to_dict()
    assert values['optim'] == [dict(lr=1e-3, betas=(0.9, 0.999))]


@pytest.mark.parametrize('text, where', [
    ("import os\nmodel = dict(type='X')", 'line 1'),
    ("model = dict(type=open('f', 'w').write('x'))", 'line 1'),
    ("model = __import__('os').system('true')", 'line 1'),
    ("model = dict(**other)", 'line 1'),
    ("x = 1\nmodel: int = 2", 'line 2'),
    ("model = [i for i in range(3)]", 'line 1'),
    ("model = dict(a=(lambda: 0))", 'line 1'),
    ("model = dict(", 'does not parse'),
])
def test_anything_but_plain_assignments_is_refused(tmp_path, text, where):
    with pytest.raises(ConfigDataError, match=where) as error:
        read_config_data(text, 'ckpt.pth (meta["cfg"])')
    assert 'ckpt.pth' in str(error.value)


def test_not_text_is_refused():
    with pytest.raises(ConfigDataError, match='not text'):
        read_config_data(b'model = 1', 'ckpt.pth')


@given(st.text(max_size=200))
def test_random_text_never_runs_and_fails_clearly(text):
    """Random text: a dict of plain values, or a ConfigDataError."""
    try:
        values = read_config_data(text, 'random')
    except ConfigDataError as error:
        assert 'random' in str(error)
    else:
        assert isinstance(values, dict)
