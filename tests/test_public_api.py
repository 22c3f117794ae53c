"""The public API is the names on two pages: ``docs/api.rst`` for the
library (``wgse_mmseg``) and ``docs/api_bench.rst`` for the measurement wing
(``wgse_bench``).

Every name a page documents exists and is in the ``__all__`` of the
module the page names it from; every ``__all__`` of every module of a
package lists only objects on its page (``__version__`` aside). A name
added to an ``__all__`` without the page, or put on the page without an
``__all__``, fails here. The library page's first part, *The plugin*, holds
what a user of the plugin needs, at most 30 names.
"""
import importlib
import os.path as osp
import pkgutil
import re

import pytest

import wgse_bench
import wgse_mmseg

wgse_mmseg.register_all_modules()

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: package -> its API page
PAGES = {wgse_mmseg: osp.join(ROOT, 'docs', 'api.rst'),
         wgse_bench: osp.join(ROOT, 'docs', 'api_bench.rst')}
DIRECTIVE = re.compile(r'^\.\. (currentmodule|auto(?:function|class|'
                       r'exception|data)):: (\S+)', re.M)
#: where the library page's first part ends
BUILDING_BLOCKS = '\nBuilding blocks\n'


def page_entries(text):
    """``(module name, name)`` of every object a page's text documents."""
    entries, module = [], None
    for kind, name in DIRECTIVE.findall(text):
        if kind == 'currentmodule':
            module = name
        else:
            entries.append((module, name))
    return entries


def _entries(package):
    return page_entries(open(PAGES[package], encoding='utf-8').read())


def _modules(package):
    """Every module of ``package`` (one whose optional dependency is absent
    is left out)."""
    yield package
    for info in pkgutil.walk_packages(package.__path__,
                                      package.__name__ + '.'):
        try:
            yield importlib.import_module(info.name)
        except ModuleNotFoundError as err:
            if err.name and err.name.split('.')[0] == package.__name__:
                raise


@pytest.mark.parametrize('package', PAGES, ids=lambda p: p.__name__)
def test_the_page_names_what_the_modules_export(package):
    entries = _entries(package)
    assert len(entries) > 15
    missing = []
    for module_name, name in entries:
        module = importlib.import_module(module_name)
        if not module_name.startswith(package.__name__) or \
                not hasattr(module, name) or name not in module.__all__:
            missing.append(f'{module_name}.{name}')
    assert not missing, f'on {PAGES[package]} but not exported: {missing}'


@pytest.mark.parametrize('package', PAGES, ids=lambda p: p.__name__)
def test_every_export_is_on_the_page(package):
    documented = {id(getattr(importlib.import_module(module), name))
                  for module, name in _entries(package)}
    extra = []
    for module in _modules(package):
        for name in getattr(module, '__all__', ()):
            if not hasattr(module, name):
                extra.append(f'{module.__name__}.{name} (missing)')
            elif name != '__version__' and \
                    id(getattr(module, name)) not in documented:
                extra.append(f'{module.__name__}.{name}')
    assert not extra, (
        f'exported but not on {PAGES[package]} (put it there, or take it '
        f'out of __all__): {extra}')


def test_the_plugin_part_is_short():
    """What a plugin user reads first: at most 32 names, before the core
    library's building blocks."""
    text = open(PAGES[wgse_mmseg], encoding='utf-8').read()
    assert BUILDING_BLOCKS in text
    first = page_entries(text.split(BUILDING_BLOCKS)[0])
    assert 20 <= len(first) <= 32, len(first)
