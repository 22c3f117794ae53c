"""``--cfg-options`` values arrive as typed (wgse_mmseg.utils.config):
mmengine's ``DictAction`` drops every space and strips quotes, so
``data_root=D/my data`` read ``D/mydata``; here spaces, quotes, backslashes
and unicode are kept, or the value is refused naming it."""
import argparse
import math

import pytest
from hypothesis import given, settings, strategies as st

from wgse_mmseg.utils.config import (MAX_OPTION_DEPTH, add_config_options,
                                     parse_option_value)


def _parse(*words):
    parser = argparse.ArgumentParser(exit_on_error=False)
    add_config_options(parser)
    return parser.parse_args(['--cfg-options', *words]).cfg_options


@pytest.mark.parametrize('text', [
    'D/my data', "D/John's data", 'D/data\'', 'ünïcødé/данные 数据',
    ' leading and trailing ', 'C:\\temp\\new', 'a=b', 'x"y', 'tab\there'])
def test_a_value_is_kept_exactly(text):
    assert parse_option_value(text) == text
    assert _parse(f'data_root={text}') == {'data_root': text}


@pytest.mark.parametrize('text, value', [
    ('41', 41), ('0.5', 0.5), ('True', True), ('false', False),
    ('None', None), ("'41'", '41'), ('"my data"', 'my data'),
    (r"'it\'s'", "it's"), ('"a,b"', 'a,b'), ('128,256', [128, 256]),
    ('[8, 16]', [8, 16]), ('(8,16)', (8, 16)), ('[]', []),
    ("[my data, 'x, y', (1, 2)]", ['my data', 'x, y', (1, 2)]),
    ("[John's, a b]", ["John's", 'a b'])])
def test_literals_lists_and_quoted_strings(text, value):
    got = parse_option_value(text)
    assert got == value and type(got) is type(value)


@pytest.mark.parametrize('text', [
    '(1', '[[1]', '1)', "'unclosed", "'it''s'", '"a"b"',
    '[' * (MAX_OPTION_DEPTH + 1) + ']' * (MAX_OPTION_DEPTH + 1)])
def test_a_value_that_cannot_be_read_as_typed_is_refused_naming_it(text):
    with pytest.raises(argparse.ArgumentError) as info:
        _parse(f'key={text}')
    assert 'key:' in str(info.value)


_PLAIN = st.text(st.characters(blacklist_categories=('Cs', ),
                               blacklist_characters='[](),\'"'), min_size=1)


@settings(max_examples=300, deadline=None)
@given(text=_PLAIN)
def test_any_plain_text_arrives_unchanged(text):
    """Text without brackets, commas or quotes is a number, a bool, None
    or itself, character for character."""
    value = parse_option_value(text)
    if isinstance(value, str):
        assert value == text
    elif value is None or isinstance(value, bool):
        assert text.lower() in ('true', 'false', 'none')
    elif isinstance(value, int):
        assert value == int(text)
    else:
        assert value == float(text) or math.isnan(value)


@settings(max_examples=200, deadline=None)
@given(items=st.lists(_PLAIN.filter(lambda t: t.strip() == t), min_size=1,
                      max_size=5))
def test_quoted_items_of_a_list_arrive_unchanged(items):
    quoted = ', '.join("'" + item.replace('\\', '\\\\') + "'"
                       for item in items)
    assert parse_option_value(f'[{quoted}]') == items
