"""The public API is the names on one page, ``docs/api.rst``.

Every name that page documents exists and is in the ``__all__`` of the
module the page names it from; every ``__all__`` of every module of the
package lists only objects on that page (``__version__`` aside). A name
added to an ``__all__`` without the page, or put on the page without an
``__all__``, fails here.
"""
import importlib
import os.path as osp
import pkgutil
import re

import wgse_mmseg

wgse_mmseg.register_all_modules()

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
PAGE = osp.join(ROOT, 'docs', 'api.rst')
DIRECTIVE = re.compile(r'^\.\. (currentmodule|auto(?:function|class|'
                       r'exception|data)):: (\S+)', re.M)


def _page_entries():
    """``(module name, name)`` of every object the page documents."""
    entries, module = [], None
    for kind, name in DIRECTIVE.findall(open(PAGE, encoding='utf-8').read()):
        if kind == 'currentmodule':
            module = name
        else:
            entries.append((module, name))
    return entries


def _modules():
    """Every module of the package (one whose optional dependency is absent
    is left out)."""
    yield wgse_mmseg
    for info in pkgutil.walk_packages(wgse_mmseg.__path__, 'wgse_mmseg.'):
        try:
            yield importlib.import_module(info.name)
        except ModuleNotFoundError as err:
            if err.name and err.name.split('.')[0] == 'wgse_mmseg':
                raise


def test_the_page_names_what_the_modules_export():
    entries = _page_entries()
    assert len(entries) > 40
    missing = []
    for module_name, name in entries:
        module = importlib.import_module(module_name)
        if not hasattr(module, name) or name not in module.__all__:
            missing.append(f'{module_name}.{name}')
    assert not missing, f'on docs/api.rst but not exported: {missing}'


def test_every_export_is_on_the_page():
    documented = {id(getattr(importlib.import_module(module), name))
                  for module, name in _page_entries()}
    extra = []
    for module in _modules():
        for name in getattr(module, '__all__', ()):
            if not hasattr(module, name):
                extra.append(f'{module.__name__}.{name} (missing)')
            elif name != '__version__' and \
                    id(getattr(module, name)) not in documented:
                extra.append(f'{module.__name__}.{name}')
    assert not extra, (
        f'exported but not on docs/api.rst (put it there, or take it out of '
        f'__all__): {extra}')
