"""dev/sweep_band_kernels.py in triton's CPU interpreter
(``TRITON_INTERPRET=1``, set in ``conftest.py``): every entry of a sweep
runs the kernels, and entries that tile the pixels differently agree."""
import json

import pytest

pytestmark = pytest.mark.needs_triton
TOOL = 'dev/sweep_band_kernels.py'


def test_each_entry_runs_and_agrees_with_the_first(load_tool, tmp_path,
                                                   capsys):
    """40 pixels: one program of 128 (partial) against three of 16 (the
    last partial); the backward with the input gradient, 32-pixel tiles
    against 16."""
    out = tmp_path / 'sweep.json'
    sweep = load_tool(TOOL)
    assert sweep.main(['--pixels', '40', '--length', '6', '--precision',
                       'ieee', '--forward', '128x4', '16x4', '--backward',
                       '16x4r255', '32x2r96', '--input-grad', '--repeat', '1',
                       '--out', str(out)]) == 0
    rows = json.loads(out.read_text())['rows']
    assert [(r['kernel'], r['entry'], r['listed']) for r in rows] == [
        ('band_forward', '128x4', True), ('band_forward', '16x4', False),
        ('band_backward', '16x4r255', True),
        ('band_backward', '32x2r96', False)]
    assert rows[0]['difference'] == rows[2]['difference'] == 0
    # the backward's parameter sums add the programs' rows in another order
    assert all(r['difference'] < 1e-5 and r['ms'] > 0 for r in rows)
    assert '| band_backward | 32x2r96' in capsys.readouterr().out


@pytest.mark.parametrize('text', ['16', '15x4', '16x3', '16x32', '16x4r8',
                                  '16x4r256', '16x4r', '9' * 400 + 'x4'])
def test_an_entry_that_cannot_launch_is_refused_naming_it(load_tool, text,
                                                          capsys):
    with pytest.raises(SystemExit) as exit:
        load_tool(TOOL).main(['--backward', '16x4', text])
    assert exit.value.code == 2
    last = capsys.readouterr().err.splitlines()[-1]
    assert 'error: argument --backward: ' in last and text[:10] in last
