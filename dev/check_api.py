"""The public API is the names on two pages, no more and no fewer:
``docs/api.rst`` for the library (``wgse_mmseg``) and ``docs/api_bench.rst``
for the measurement wing (``wgse_bench``).

    python dev/check_api.py

Every name a page documents exists and is in the ``__all__`` of the module
the page names it from; every ``__all__`` of every module of a package
lists only objects on its page (``__version__`` aside). The library page's
first part, *The plugin*, holds what a user of the plugin needs: between
:data:`PLUGIN_NAMES` names. Prints each difference; the exit status is 1
where there is one. ``bash tools/lint.sh`` runs it.
"""
import argparse
import importlib
import os.path as osp
import pkgutil
import re
import sys
from typing import List, Optional, Tuple

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: package name -> its API page, from the root
PAGES = {'wgse_mmseg': 'docs/api.rst', 'wgse_bench': 'docs/api_bench.rst'}
#: a page's directive that names a module or documents an object
DIRECTIVE = re.compile(r'^\.\. (currentmodule|auto(?:function|class|'
                       r'exception|data)):: (\S+)', re.M)
#: where the library page's first part, *The plugin*, ends
BUILDING_BLOCKS = '\nBuilding blocks\n'
#: the fewest and the most names *The plugin* may hold
PLUGIN_NAMES = (20, 32)
#: fewer entries than this on a page: its directives were misread
MIN_ENTRIES = 16


def page_entries(text: str) -> List[Tuple[str, str]]:
    """``(module name, name)`` of every object a page's text documents."""
    entries, module = [], None
    for kind, name in DIRECTIVE.findall(text):
        if kind == 'currentmodule':
            module = name
        else:
            entries.append((module, name))
    return entries


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


def api_problems(package_name: str, page_text: str) -> List[str]:
    """Where a page's text and the ``__all__`` lists of the package differ:
    a name the page documents that its module lacks or leaves out of
    ``__all__`` (or one of a module outside the package), a name of an
    ``__all__`` of any module of the package that is not an object on the
    page, and an ``__all__`` entry the module lacks. Imports every module
    of the package."""
    problems, documented = [], set()
    for module_name, name in page_entries(page_text):
        module = importlib.import_module(module_name)
        if hasattr(module, name):
            documented.add(id(getattr(module, name)))
        if not module_name.startswith(package_name) or \
                not hasattr(module, name) or \
                name not in getattr(module, '__all__', ()):
            problems.append(f'{module_name}.{name}: on the page but not '
                            f'exported')
    for module in _modules(importlib.import_module(package_name)):
        for name in getattr(module, '__all__', ()):
            if not hasattr(module, name):
                problems.append(f'{module.__name__}.{name}: in __all__ but '
                                f'missing')
            elif name != '__version__' and \
                    id(getattr(module, name)) not in documented:
                problems.append(f'{module.__name__}.{name}: exported but '
                                f'not on the page (put it there, or take it '
                                f'out of __all__)')
    return problems


def plugin_part_problems(page_text: str) -> List[str]:
    """The library page's part before *Building blocks* holds between
    :data:`PLUGIN_NAMES` names."""
    if BUILDING_BLOCKS not in page_text:
        return [f'no {BUILDING_BLOCKS.strip()!r} heading ends The plugin']
    count = len(page_entries(page_text.split(BUILDING_BLOCKS)[0]))
    low, high = PLUGIN_NAMES
    if not low <= count <= high:
        return [f'The plugin documents {count} names, not {low} to {high}']
    return []


def build_parser() -> argparse.ArgumentParser:
    return argparse.ArgumentParser(description=__doc__.split('\n\n')[0])


def main(argv: Optional[List[str]] = None) -> int:
    build_parser().parse_args(argv)
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)
    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # the MMSeg layer's modules import
    problems = []
    for package_name, page in PAGES.items():
        text = open(osp.join(ROOT, page), encoding='utf-8').read()
        found = api_problems(package_name, text)
        if len(page_entries(text)) < MIN_ENTRIES:
            found.append(f'only {len(page_entries(text))} entries read')
        if package_name == 'wgse_mmseg':
            found += plugin_part_problems(text)
        problems += [f'{page}: {problem}' for problem in found]
    for problem in problems:
        print(problem)
    return 1 if problems else 0


if __name__ == '__main__':
    sys.exit(main())
