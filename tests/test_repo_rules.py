"""The repository's checks (``dev/check_references.py``,
``dev/check_floors.py``, ``dev/check_api.py``, ``dev/check_docs.py``, which
``bash tools/lint.sh`` runs on the tree) each find what they are there to
find: each is fed a small tree that breaks it, and one that keeps it."""
import textwrap

import pytest


@pytest.fixture(scope='module')
def references(load_tool):
    return load_tool('dev/check_references.py')


@pytest.fixture(scope='module')
def floors(load_tool):
    return load_tool('dev/check_floors.py')


@pytest.fixture(scope='module')
def api(load_tool):
    return load_tool('dev/check_api.py')


@pytest.fixture(scope='module')
def docs(load_tool):
    return load_tool('dev/check_docs.py')


def _write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text))
    return str(path)


def test_a_reference_to_nothing_is_found(references, tmp_path, monkeypatch):
    """A role naming a missing object of the package, of the module itself
    or no module at all, and a path that is not there, in a docstring and
    on a page; what exists passes."""
    monkeypatch.syspath_prepend(str(tmp_path))
    module = _write(tmp_path / 'tools' / 'refs_tool.py', '''\
        """See :func:`wgse_mmseg.register_all_modules`, :func:`present`,
        :class:`Holder`, :meth:`method`, ``tools/refs_tool.py``; broken:
        :func:`wgse_mmseg.no_such_name`, :func:`absent` and
        ``tools/no_such_tool.py``."""


        def present():
            """Nothing more: :mod:`wgse_mmseg.nowhere.at_all`."""


        class Holder:
            def method(self):
                pass
        ''')
    page = _write(tmp_path / 'docs' / 'page.md',
                  'Run `tools/refs_tool.py`, not `dev/gone.sh`.\n')
    assert references.broken_references([module], [page], str(tmp_path)) == [
        'docs/page.md: dev/gone.sh',
        'tools/refs_tool.py: absent',
        'tools/refs_tool.py: tools/no_such_tool.py',
        'tools/refs_tool.py: wgse_mmseg.no_such_name',
        'tools/refs_tool.py: wgse_mmseg.nowhere.at_all']


def _library(root, files):
    for name, text in files.items():
        _write(root / 'wgse_mmseg' / name, text)


def test_an_import_up_a_floor_or_into_the_wing_is_found(floors, tmp_path):
    """A deferred relative import (the kind that ran from ``utils`` up to
    ``engine``), an absolute one, an import of the wing and a package on no
    floor; imports down a floor pass."""
    _library(tmp_path, {
        'utils/distributed.py': 'def f():\n    from .. import engine\n',
        'utils/other.py': 'import wgse_mmseg.apis.inferencer\n'
                          'from wgse_mmseg.core import wavelets\n',
        'core/bench.py': 'from wgse_bench import timing\n',
        'engine/hooks.py': 'from ..utils import distributed\n',
        'attic/old.py': '',
    })
    problems = floors.floor_problems(
        floors.library_modules(str(tmp_path)), str(tmp_path))
    assert problems == [
        'put attic on a floor of FLOORS (what it imports decides which)',
        'wgse_mmseg/core/bench.py:1: imports the measurement wing '
        '(wgse_bench)',
        'wgse_mmseg/core/bench.py:1: imports the measurement wing '
        '(wgse_bench.timing)',
        'wgse_mmseg/utils/distributed.py:2: utils imports '
        'wgse_mmseg.engine, a floor above it',
        'wgse_mmseg/utils/other.py:1: utils imports '
        'wgse_mmseg.apis.inferencer, a floor above it']


def test_a_private_module_imported_from_another_package_is_found(
        floors, tmp_path):
    """A private module reached from another package of the library and
    from a tool is found; one reached from its own package passes."""
    _library(tmp_path, {
        'core/wgse/_kernels.py': '',
        'core/wgse/backends.py': 'from . import _kernels\n',
        'utils/probe.py': 'from ..core.wgse import _kernels\n',
    })
    (tmp_path / 'tools').mkdir()
    (tmp_path / 'tools' / 'tool.py').write_text(
        'from wgse_mmseg._stack import check\n')
    assert floors.private_problems(str(tmp_path)) == [
        'tools/tool.py:1: imports wgse_mmseg._stack, private to its package',
        'tools/tool.py:1: imports wgse_mmseg._stack.check, private to its '
        'package',
        'wgse_mmseg/utils/probe.py:1: imports '
        'wgse_mmseg.core.wgse._kernels, private to its package']


def test_the_api_page_and_the_exports_must_agree(api, tmp_path,
                                                 monkeypatch):
    """A name on the page that its module does not export, one it lacks, a
    name exported from a submodule but not on the page, and a stale
    ``__all__`` entry."""
    monkeypatch.syspath_prepend(str(tmp_path))
    _write(tmp_path / 'apipkg' / '__init__.py', '''\
        __all__ = ['shown', '__version__']
        __version__ = '0'
        def shown(): pass
        def internal(): pass
        ''')
    _write(tmp_path / 'apipkg' / 'sub.py', '''\
        __all__ = ['exported', 'gone']
        def exported(): pass
        ''')
    page = textwrap.dedent('''\
        .. currentmodule:: apipkg

        .. autofunction:: shown
        .. autofunction:: internal
        .. autofunction:: nowhere
        ''')
    assert api.page_entries(page) == [
        ('apipkg', 'shown'), ('apipkg', 'internal'), ('apipkg', 'nowhere')]
    assert api.api_problems('apipkg', page) == [
        'apipkg.internal: on the page but not exported',
        'apipkg.nowhere: on the page but not exported',
        'apipkg.sub.exported: exported but not on the page (put it there, '
        'or take it out of __all__)',
        'apipkg.sub.gone: in __all__ but missing']
    _write(tmp_path / 'agreeing' / '__init__.py', '''\
        __all__ = ['shown']
        def shown(): pass
        ''')
    _write(tmp_path / 'agreeing' / 'sub.py', '''\
        __all__ = ['exported']
        def exported(): pass
        def internal(): pass
        ''')
    assert api.api_problems('agreeing', textwrap.dedent('''\
        .. currentmodule:: agreeing

        .. autofunction:: shown

        .. currentmodule:: agreeing.sub

        .. autofunction:: exported
        ''')) == []


def test_the_plugin_part_is_held_short(api):
    entry = '.. autofunction:: f\n'
    low, high = api.PLUGIN_NAMES
    rest = api.BUILDING_BLOCKS + entry * 50
    assert api.plugin_part_problems(entry * low + rest) == []
    assert api.plugin_part_problems(entry * high + rest) == []
    assert api.plugin_part_problems(entry * (high + 1) + rest) == [
        f'The plugin documents {high + 1} names, not {low} to {high}']
    assert api.plugin_part_problems(entry * low) == [
        "no 'Building blocks' heading ends The plugin"]


def test_the_page_check_finds_an_internal_name(docs):
    """What the page check reads: code text, dotted names of the package
    but not paths; a constant of a documented module is not API."""
    page = ('<p><code class="docutils literal"><span>wgse_mmseg.fileio.'
            'spike_files.SPIKE_FORMATS</span></code> and <code>wgse_mmseg/'
            'fileio/spike_files.py</code>, <code>wgse_mmseg.fileio.'
            'load_spikes()</code></p>')
    names = docs.shown_names(page)
    assert names == {'wgse_mmseg.fileio.spike_files.SPIKE_FORMATS',
                     'wgse_mmseg.fileio.load_spikes'}
    inventory = {'wgse_mmseg.fileio.load_spikes', 'wgse_mmseg.core.WGSE'}
    assert docs.not_api(names, inventory) == [
        'wgse_mmseg.fileio.spike_files.SPIKE_FORMATS']
    assert docs.not_api({'wgse_mmseg.core', 'wgse_mmseg.core.WGSE.backend'},
                        inventory) == []


def test_a_check_that_finds_something_exits_with_1(references, floors,
                                                   tmp_path, monkeypatch,
                                                   capsys):
    """The command lines over the checks: each problem printed, exit
    status 1; a tree that keeps the rules: 0."""
    _library(tmp_path, {'core/bench.py': 'import wgse_bench\n'})
    _write(tmp_path / 'README.md', 'See `tools/gone.py`.\n')
    monkeypatch.syspath_prepend(str(tmp_path))  # as main would put it
    monkeypatch.setattr(floors, 'ROOT', str(tmp_path))
    monkeypatch.setattr(references, 'ROOT', str(tmp_path))
    assert floors.main([]) == 1 and references.main([]) == 1
    assert capsys.readouterr().out.splitlines() == [
        'wgse_mmseg/core/bench.py:1: imports the measurement wing '
        '(wgse_bench)', 'broken reference: README.md: tools/gone.py']
    _write(tmp_path / 'wgse_mmseg' / 'core' / 'bench.py', '')
    _write(tmp_path / 'README.md', 'See `wgse_mmseg/core/bench.py`.\n')
    assert floors.main([]) == 0 and references.main([]) == 0
