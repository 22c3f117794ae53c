"""``--cfg-options`` values (wgse_mmseg.utils.config) read as mmengine's
``DictAction`` reads them, compared with it over a table, except that the
spaces inside a value are kept (``DictAction`` reads ``data_root=D/my
data`` as ``D/mydata``); an ambiguous value is refused naming its key."""
import argparse
import re

import pytest
from hypothesis import given, settings, strategies as st

from wgse_mmseg.utils.config import (MAX_OPTION_DEPTH, add_config_options,
                                     parse_option_value)


def _parse(*words):
    parser = argparse.ArgumentParser(exit_on_error=False)
    add_config_options(parser)
    return parser.parse_args(['--cfg-options', *words]).cfg_options


#: values DictAction reads right: the package reads each the same
DICT_ACTION_TABLE = [
    '41', '-3', '0', '+7', '1_000', '0.5', '-2.5', '1e3', '-1e-3', 'inf',
    'True', 'false', 'TRUE', 'None', 'none', 'abc', 'D/data', "John's",
    'x"y', '"3"', "'None'", "'true'", '"[1,2]"', "'a,b'", '"\'41\'"',
    '[1,2]', '[1, 2]', '[ True ]', ' True', ' 3 ', '(1,2)', '(1,)',
    '( 1 , 2 )', '[]', '()', '[ ]', '[(1,2),[3]]', '[[[]]]',
    '[(1, 2), [3, [4, (5,)]], x]', '1,2', '128,256', 'a,b,c', '1,2,',
    '[1,]', 'a,,b', "['a', 'b']", '["x", 1, None]', '[1.5,-2,1e3]',
    '(a,[b,c])', 'dict', '',
]


@pytest.mark.parametrize('text', DICT_ACTION_TABLE)
def test_values_read_as_mmengines_dict_action_reads_them(text):
    """The reference is mmengine's own parser, run on the same text."""
    from mmengine.config import DictAction
    expected = DictAction._parse_iterable(text)
    got = parse_option_value(text)
    assert got == expected and repr(got) == repr(expected)
    assert _parse(f'k={text}') == {'k': expected}


@pytest.mark.parametrize('text, value', [
    ('D/my data', 'D/my data'), ("D/John's data", "D/John's data"),
    ('ünïcødé/данные 数据', 'ünïcødé/данные 数据'),
    (' leading and trailing ', 'leading and trailing'),
    ('"my data"', 'my data'),
    ('[my data, x y]', ['my data', 'x y']),
    ('(a b, [c d])', ('a b', ['c d']))])
def test_spaces_inside_a_value_are_kept(text, value):
    """The one difference from DictAction, which drops every space
    (``D/my data`` would be ``D/mydata``); those around a value or an
    item go, as there."""
    from mmengine.config import DictAction
    assert DictAction._parse_iterable(text) != value
    assert parse_option_value(text) == value
    assert _parse(f'k={text}') == {'k': value}


@pytest.mark.parametrize('text', [
    '(1', '[[1]', '1)', '[1,2))', "'unclosed", 'closed"', '"a,b",c',
    '["a,b"]', '1 000', 'Tr ue', 'No ne', '[1 2]', '- 4',
    '[' * (MAX_OPTION_DEPTH + 1) + ']' * (MAX_OPTION_DEPTH + 1)])
def test_an_ambiguous_value_is_refused_naming_the_key(text):
    """Unbalanced brackets, a quote DictAction would drop unmatched or a
    comma it would split inside quotes, and a string whose spaces hide a
    number, a bool or None: refused, never guessed."""
    with pytest.raises(argparse.ArgumentError) as info:
        _parse(f'train_cfg.max_epochs={text}')
    assert 'train_cfg.max_epochs:' in str(info.value)


def test_a_quoted_number_reaches_the_config_as_a_number(tmp_path):
    """End to end: ``train_cfg.max_epochs="2"`` (the quotes kept by the
    shell's single quotes) is the loop's 2, not '2'."""
    from wgse_mmseg.utils.config import load_config
    config = tmp_path / 'c.py'
    config.write_text('train_cfg = dict(max_epochs=1)\n')
    options = _parse('train_cfg.max_epochs="2"', 'x=\'None\'')
    cfg = load_config(str(config), options)
    assert cfg.train_cfg.max_epochs == 2 and cfg.x is None


_TEXT = st.text(st.sampled_from('ab1.e-+_[](),\'" TrueNon'), max_size=12)


@settings(max_examples=500, deadline=None)
@given(text=_TEXT)
def test_any_value_reads_as_dict_action_or_is_refused(text):
    """Over texts made of numbers, words, brackets, commas, quotes and
    spaces: the package's value is DictAction's wherever the text has no
    space, or the package refused it as ambiguous (or DictAction fails).
    With spaces, DictAction drops them all, after stripping quotes, so
    ``D/my data`` is ``D/mydata`` and ``'1' `` is ``"1'"`` there."""
    from mmengine.config import DictAction
    try:
        got = parse_option_value(text)
    except ValueError:
        return
    try:
        expected = DictAction._parse_iterable(text)
    except (AssertionError, RecursionError):
        return  # DictAction fails: brackets inside a word, as in 'a(b,c)'
    if repr(got) != repr(expected):  # DictAction drops the spaces first
        assert ' ' in text  # (after quotes: "'1' " is "1'" there)


def test_every_tool_reads_cfg_options_with_the_one_parser():
    """A tool that takes ``--cfg-options`` adds it through
    ``add_config_options`` (or ``add_runner_arguments``, which calls it):
    no tool declares its own or uses DictAction."""
    import pathlib
    root = pathlib.Path(__file__).parents[2]
    users = []
    for path in sorted((root / 'tools').rglob('*.py')):
        source = path.read_text()
        assert 'DictAction' not in source, path
        if re.search(r"add_argument\(\s*'--cfg-options'", source):
            raise AssertionError(f'{path} declares its own --cfg-options')
        if re.search(r'add_(config_options|runner_arguments)\(', source):
            users.append(path.relative_to(root).as_posix())
    assert {'tools/train.py', 'tools/test.py', 'tools/demo.py',
            'tools/analysis_tools/benchmark.py',
            'tools/analysis_tools/run_experiments.py',
            'tools/deployment/pytorch2onnx.py'} <= set(users)
