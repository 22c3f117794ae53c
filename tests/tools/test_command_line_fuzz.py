"""Every option of every tool's command line, fuzzed in-process.

Each tool builds its parser with ``build_parser()``, and every option that
takes a value is typed with a kind of :mod:`wgse_mmseg.command_line` or
is ``--cfg-options`` (:class:`wgse_mmseg.utils.config.ConfigOptions`,
whose spike settings are declared too). For every option, hypothesis draws
wrong types as text, NaN, Inf, negative, zero, huge and fractional numbers,
quotes and backslashes, the declaration's own boundaries and, for paths, a
directory, an empty file, a text file and a missing file. The parser either
exits with status 2 and a last line ``<prog>: error: argument <option>: ...``
naming the option, or accepts the word, and then only where an independent
reading of the declaration (below) accepts it, with the value it spells;
each parse within time and memory bounds.
"""
import argparse
import contextlib
import functools
import glob
import importlib
import importlib.util
import io
import math
import os.path as osp
import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wgse_mmseg.command_line import (LAYOUT, Argument, Choice, Integer, Number,
                                     OneOf, Path, SequenceOf, Text)
from wgse_mmseg.limits import MAX_IMAGE_SIDE, MAX_NUM_STEPS, MAX_SAMPLES
from wgse_mmseg.data_generation.shards import Shard, ShardArgument
from wgse_mmseg.utils.config import SPIKE_SETTING_KINDS, ConfigOptions

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))
#: the scripts under tools/ (users') and dev/ (maintainers'), and the
#: modules of the library and the measurement wing with a command line
TOOL_FILES = sorted(osp.relpath(p, ROOT) for room in ('tools', 'dev')
                    for p in glob.glob(osp.join(ROOT, room, '**', '*.py'),
                                       recursive=True))
TOOL_MODULES = ['wgse_bench.model_bases', 'wgse_bench.reconstruction',
                'wgse_bench.wgse_memory',
                'wgse_bench.triton_resources', 'wgse_bench.kernel_prediction',
                'wgse_mmseg.data_generation.training_images']
TOOLS = TOOL_FILES + TOOL_MODULES

#: seconds and bytes of peak memory one parse may add (a parse takes
#: milliseconds; the bounds catch a declaration that allocates or loops)
TIME_BOUND_S = 5
MEMORY_BOUND = 256 << 20

FILES = {}


@pytest.fixture(scope='module', autouse=True)
def _files(wrong_file_kinds):
    FILES.update(wrong_file_kinds)
    yield


@functools.lru_cache(maxsize=None)
def _module(tool):
    if tool in TOOL_MODULES:
        return importlib.import_module(tool)
    name = 'tool_' + tool[:-len('.py')].replace('/', '_')
    spec = importlib.util.spec_from_file_location(name, osp.join(ROOT, tool))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _parser(tool) -> argparse.ArgumentParser:
    return _module(tool).build_parser()


def _valued(parser):
    """The actions that take a value (not ``--help`` or flags)."""
    return [a for a in parser._actions if a.nargs != 0]


def _display(action):
    """How argparse names ``action`` in an error."""
    if action.option_strings:
        return '/'.join(action.option_strings)
    return action.metavar or action.dest


def test_every_command_line_is_declared():
    assert len(TOOL_FILES) >= 11 and 'tools/misc/reconstruct.py' in TOOL_FILES
    for tool in TOOLS:
        parser = _parser(tool)
        for action in _valued(parser):
            assert isinstance(action.type, Argument) or isinstance(
                action, ConfigOptions), (
                    f'{tool}: {_display(action)} has no declared type')
            assert action.choices is None, (
                f'{tool}: {_display(action)}: use type=Choice(...)')
    # every module of the package that builds a parser is listed (the WGSE
    # benchmark's worker reads words its own driver writes)
    building = {osp.relpath(p, ROOT)
                for package in ('wgse_mmseg', 'wgse_bench')
                for p in glob.glob(osp.join(ROOT, package, '**', '*.py'),
                                   recursive=True)
                if 'ArgumentParser(' in open(p).read()}
    listed = {m.replace('.', '/') + '.py' for m in TOOL_MODULES}
    assert building - listed == {'wgse_bench/wgse.py'}


def _source(tool):
    path = (tool.replace('.', '/') + '.py' if tool in TOOL_MODULES
            else tool)
    return open(osp.join(ROOT, path), encoding='utf-8').read()


#: the tools that read a user's recording: each takes ``--layout``
RECORDING_READERS = {'tools/demo.py', 'tools/misc/reconstruct.py',
                     'dev/make_reconstruction_figure.py',
                     'wgse_bench.reconstruction'}


def test_every_tool_reading_a_recording_takes_the_declared_layout():
    """``--layout`` of the one declared kind on every tool that reads a
    spike file through the readers (the simulator benchmark reads only the
    files it has just written, which record their layout)."""
    reading = re.compile(r"load_spikes\(|spike_shape\(|LoadSpikeImagePair\("
                         r"|'LoadSpikeFromFile'")
    found = {tool for tool in TOOLS if reading.search(_source(tool))}
    assert found == RECORDING_READERS
    for tool in RECORDING_READERS:
        action, = [a for a in _valued(_parser(tool))
                   if a.option_strings == ['--layout']]
        assert action.type is LAYOUT and action.default is None, tool
    assert LAYOUT.choices == ('THW', 'HWT')


# ---- an independent reading of what each declaration accepts as a word ----

def _accepted(kind, word):
    """``(True, value)`` where ``kind`` must accept the command-line word
    ``word`` (and the value it spells), else ``(False, None)``."""
    no = (False, None)
    if isinstance(kind, Integer):
        try:
            value = int(word)
        except ValueError:
            return no
        ok = ((kind.minimum is None or value >= kind.minimum) and
              (kind.maximum is None or value <= kind.maximum) and
              (not kind.odd or value % 2 == 1))
        return (True, value) if ok else no
    if isinstance(kind, Number):
        try:
            value = float(word)
        except ValueError:
            return no
        ok = (math.isfinite(value) and
              (kind.minimum is None or value > kind.minimum or
               (value == kind.minimum and not kind.strict_minimum)) and
              (kind.maximum is None or value <= kind.maximum))
        return (True, value) if ok else no
    if isinstance(kind, Choice):
        matches = [c for c in kind.choices if str(c) == word]
        return (True, matches[0]) if matches else no
    if isinstance(kind, Path):
        ok = word != '' and '\0' not in word and (
            kind.exists is None or
            (osp.isfile if kind.exists == 'file' else osp.isdir)(word))
        return (True, word) if ok else no
    if isinstance(kind, Text):
        return (True, word) if kind.empty or word else no
    if isinstance(kind, OneOf):
        for alternative in kind.alternatives:
            ok, value = _accepted(alternative, word)
            if ok:
                return ok, value
        return no
    if isinstance(kind, SequenceOf):
        parts = word.split(kind.separator)
        if len(parts) < kind.min_length or (
                kind.max_length is not None and len(parts) > kind.max_length):
            return no
        items = (kind.item if isinstance(kind.item, (list, tuple)) else
                 [kind.item] * len(parts))
        read = [_accepted(item, part) for item, part in zip(items, parts)]
        if not all(ok for ok, _ in read):
            return no
        values = tuple(value for _, value in read)
        if kind.ordered and any(a > b for a, b in zip(values, values[1:])):
            return no
        return True, values
    if isinstance(kind, ShardArgument):
        parts = word.split('/')
        try:
            index, count = (int(part) for part in parts)
        except ValueError:
            return no
        ok = len(parts) == 2 and 1 <= index <= count <= MAX_SAMPLES
        return (True, Shard(index, count)) if ok else no
    raise AssertionError(f'no reading of {kind!r}')


def _valid_word(kind):
    """A word ``kind`` accepts, for the options a test does not fuzz."""
    if isinstance(kind, Path):
        return FILES['text']
    if isinstance(kind, Choice):
        return str(kind.choices[0])
    if isinstance(kind, Integer):
        return str(max(kind.minimum or 0, 1))
    if isinstance(kind, Text):
        return 'a'
    raise AssertionError(f'give the test a valid word for {kind!r}')


def _boundaries(kind):
    """Words at and just past the edges of what ``kind`` accepts."""
    if isinstance(kind, (Integer, Number)):
        words = []
        for edge in (kind.minimum, kind.maximum):
            if edge is not None:
                words += [str(edge), str(edge - 1), str(edge + 1)]
        return words
    if isinstance(kind, Choice):
        return [str(c) for c in kind.choices] + [
            str(c).upper() + ' ' for c in kind.choices]
    if isinstance(kind, OneOf):
        return [w for a in kind.alternatives for w in _boundaries(a)]
    if isinstance(kind, SequenceOf):
        items = (kind.item if isinstance(kind.item, (list, tuple)) else
                 [kind.item] * max(kind.min_length, 2))
        per_item = [_boundaries(item) or ['1'] for item in items]
        return [kind.separator.join(words[i % len(words)]
                                    for words in per_item)
                for i in range(3)] + [kind.separator.join(per_item[0][:1])]
    return []


BAD_WORDS = ['nan', 'NaN', 'inf', '-inf', 'Infinity', '0', '-0', '-1',
             '-0.5', '0.5', '1.5', '1e8', '1e300', '2147483648',
             str(2**63), str(10**18), '9' * 400, 'True', 'None', '', ' ',
             "it's", '"quoted"', 'back\\slash', '1,2', '1,"\\', '1x2x3x4',
             '0x41x8x8', '\0', 'a\0b']


def _words(kind):
    files = st.sampled_from(['directory', 'empty', 'text', 'missing']).map(
        lambda name: FILES[name])
    words = st.one_of(
        st.sampled_from(BAD_WORDS),
        st.integers(-10**20, 10**20).map(str),
        st.floats().map(repr),
        st.text(alphabet='\'"\\ab/.,x019e- \0', max_size=10),
        files)
    boundaries = _boundaries(kind)
    if boundaries:
        words = st.one_of(words, st.sampled_from(boundaries))
    if isinstance(kind, Path):  # mostly wrong file kinds for paths
        words = st.one_of(files, files, words)
    return words.filter(lambda word: word != '--')


def _argv(parser, action, words):
    """A command line of ``parser``: every required argument valid, and
    ``action`` given ``words`` (options as ``--option=WORD``, so that a word
    starting with ``-`` is still its value; positionals after ``--``)."""
    options, positionals = [], []
    for other in _valued(parser):
        given = other is action
        if other.option_strings:
            if given and len(words) == 1 and not isinstance(other.nargs, int):
                options.append(f'{other.option_strings[0]}={words[0]}')
            elif given:
                options += [other.option_strings[0], *words]
            elif other.required:  # as many words as it takes
                count = other.nargs if isinstance(other.nargs, int) else 1
                options += [other.option_strings[0],
                            *[_valid_word(other.type)] * count]
        elif given:
            positionals += words
        elif other.nargs not in ('?', '*'):
            positionals.append(_valid_word(other.type))
    return options + (['--'] + positionals if positionals else [])


def _parse(parser, argv):
    """``(namespace, None)``, or ``(None, (exit code, stderr))``."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), \
            contextlib.redirect_stdout(io.StringIO()):
        try:
            return parser.parse_args(argv), None
        except SystemExit as exit:
            return None, (exit.code, err.getvalue())


def _refusal(parser, failure, action):
    """Assert ``failure`` is argparse's one-line error naming ``action``."""
    code, stderr = failure
    assert code == 2, stderr
    last = stderr.rstrip('\n').split('\n')[-1]
    assert last.startswith(
        f'{parser.prog}: error: argument {_display(action)}: '), stderr
    return last


def _declared_options():
    for tool in TOOLS:
        for action in _valued(_parser(tool)):
            if isinstance(action.type, Argument):
                yield pytest.param(tool, action.dest,
                                   id=f'{tool}:{_display(action)}')


@pytest.mark.parametrize('tool, dest', list(_declared_options()))
def test_bad_words(tool, dest, bounded):
    parser = _parser(tool)
    action, = [a for a in _valued(parser) if a.dest == dest]
    count = action.nargs if isinstance(action.nargs, int) else 1

    @settings(max_examples=12, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(word=_words(action.type))
    def check(word):
        argv = _argv(parser, action, [word] * count)
        with bounded(TIME_BOUND_S, MEMORY_BOUND):
            args, failure = _parse(parser, argv)
        should, value = _accepted(action.type, word)
        if failure is not None:
            last = _refusal(parser, failure, action)
            assert not should, f'{word!r} refused but declared: {last}'
            return
        assert should, (f'{tool} {_display(action)} accepted {word!r}, '
                        f'which {action.type!r} refuses')
        got = getattr(args, dest)
        if action.nargs in ('+', '*') or isinstance(action.nargs, int):
            assert list(got) == [value] * count
        else:
            assert got == value and type(got) is type(value)

    check()


def _config_options():
    for tool in TOOLS:
        for action in _valued(_parser(tool)):
            if isinstance(action, ConfigOptions):
                for key in sorted(SPIKE_SETTING_KINDS):
                    yield pytest.param(tool, action.dest, key,
                                       id=f'{tool}:{key}')


@pytest.mark.parametrize('tool, dest, key', list(_config_options()))
def test_bad_spike_settings(tool, dest, key, bounded):
    """``--cfg-options KEY=WORD``: refused naming the option and the key,
    or read as a setting within its declaration and the stated limits."""
    parser = _parser(tool)
    action, = [a for a in _valued(parser) if a.dest == dest]
    kind = SPIKE_SETTING_KINDS[key]
    words = st.one_of(_words(kind), st.sampled_from(
        ['(1', '[[1]', '((1))', '(' * 300 + ')' * 300, '128,256', '[8,16]',
         '(8,16)', '8,16,32', "'41'", '"41"', '4 1', '1e3', '0,8']))

    @settings(max_examples=15, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(word=words)
    def check(word):
        argv = _argv(parser, action, [f'{key}={word}'])
        with bounded(TIME_BOUND_S, MEMORY_BOUND):
            args, failure = _parse(parser, argv)
        if failure is not None:
            last = _refusal(parser, failure, action)
            assert key in last
            return
        value = getattr(args, dest)[key]
        if key == 'num_steps':
            assert type(value) is int and 1 <= value <= MAX_NUM_STEPS
        elif key == 'crop_size':
            sizes = [value] * 2 if isinstance(value, int) else list(value)
            assert len(sizes) == 2 and all(
                type(s) is int and 1 <= s <= MAX_IMAGE_SIDE for s in sizes)
        else:
            assert isinstance(value, str) and value and '\0' not in value

    check()
