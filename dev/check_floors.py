"""No import of the library runs up a floor or into the measurement wing
(docs/architecture.md, "Floors").

    python dev/check_floors.py

Every ``import`` statement of every module of ``wgse_mmseg``, at module
level or inside a function, is read from the source (nothing is imported):
a module may import its own package and the packages of the floors below
its own (:data:`FLOORS`), never one above, and never ``wgse_bench``. The
wing imports the library as any user's script would. Every package must be
on a floor, and a private module (``_name``) is imported only from its own
package, never from the library's others, the wing, the tools or ``dev/``.
Prints each import that breaks the floors; the exit status is 1 where there
is one. ``bash tools/lint.sh`` runs it.
"""
import argparse
import ast
import glob
import importlib.util
import os.path as osp
import sys
from typing import Iterable, Iterator, List, Optional, Tuple

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))

#: the library's packages (and top-level modules) from the ground floor up
FLOORS = (
    ('version', 'errors', 'limits', 'argument_checks', 'command_line'),
    ('core',),
    ('fileio',),
    ('data_generation',),
    ('compat',),
    ('openmmlab_stack',),
    ('utils',),
    ('datasets', 'evaluation', 'models'),
    ('engine',),
    ('apis',),
    ('mmseg_layer', '__init__'),
)


def imports(path: str, package: str) -> Iterator[Tuple[int, str]]:
    """``(line, dotted name)`` of every name ``path``'s import statements
    name (``from a import b`` gives ``a`` and ``a.b``), relative names
    resolved in ``package``."""
    tree = ast.parse(open(path, encoding='utf-8').read(), path)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                base = importlib.util.resolve_name(
                    '.' * node.level + base, package)
            yield node.lineno, base
            for alias in node.names:
                yield node.lineno, f'{base}.{alias.name}'


def library_modules(root: str) -> Iterator[Tuple[str, str, str]]:
    """``(path, package, floor name)`` of every module of ``wgse_mmseg``
    under ``root`` (the floor name: the package or top-level module of
    ``wgse_mmseg`` it is in)."""
    for path in sorted(glob.glob(osp.join(root, 'wgse_mmseg', '**', '*.py'),
                                 recursive=True)):
        parts = osp.relpath(path, root)[:-3].split(osp.sep)
        yield path, '.'.join(parts[:-1]), parts[1]


def floor_problems(modules: Iterable[Tuple[str, str, str]], root: str,
                   floors=FLOORS) -> List[str]:
    """What breaks ``floors`` among ``modules`` (as :func:`library_modules`
    gives them): a package on no floor, an import of ``wgse_bench``, an
    import of a package on a floor above the module's own."""
    level = {name: floor for floor, names in enumerate(floors)
             for name in names}
    modules = list(modules)
    problems = [f'put {name} on a floor of FLOORS (what it imports decides '
                f'which)'
                for name in sorted({floor for _, _, floor in modules
                                    if floor not in level})]
    for path, package, floor in modules:
        where = osp.relpath(path, root)
        for line, name in imports(path, package):
            top, _, rest = name.partition('.')
            if top == 'wgse_bench':
                problems.append(f'{where}:{line}: imports the measurement '
                                f'wing ({name})')
            elif top == 'wgse_mmseg' and rest:
                target = rest.split('.')[0]
                if level.get(target, 0) > level.get(floor, 0):
                    problems.append(f'{where}:{line}: {floor} imports '
                                    f'{name}, a floor above it')
    return problems


def _package_of(name: str) -> str:
    """The package of the library a dotted name is in (``wgse_mmseg.core``
    of ``wgse_mmseg.core.wgse.wgse``)."""
    return '.'.join(name.split('.')[:2])


def private_problems(root: str) -> List[str]:
    """Each import of a private module or name of the library (a part
    ``_name``) from outside the package it belongs to, in the library, the
    wing, the tools and ``dev/``."""
    problems = []
    patterns = ('wgse_mmseg/**/*.py', 'wgse_bench/**/*.py', 'tools/**/*.py',
                'dev/*.py')
    paths = sorted(path for pattern in patterns for path in
                   glob.glob(osp.join(root, pattern), recursive=True))
    for path in paths:
        parts = osp.relpath(path, root)[:-3].split(osp.sep)
        package = '.'.join(parts[:-1])
        for line, name in imports(path, package):
            private = any(part.startswith('_') and not part.startswith('__')
                          for part in name.split('.'))
            if name.startswith('wgse_mmseg.') and private and \
                    _package_of(name) != _package_of(package):
                problems.append(f'{osp.relpath(path, root)}:{line}: '
                                f'imports {name}, private to its package')
    return problems


def build_parser() -> argparse.ArgumentParser:
    return argparse.ArgumentParser(description=__doc__.split('\n\n')[0])


def main(argv: Optional[List[str]] = None) -> int:
    build_parser().parse_args(argv)
    problems = (floor_problems(library_modules(ROOT), ROOT) +
                private_problems(ROOT))
    for problem in problems:
        print(problem)
    return 1 if problems else 0


if __name__ == '__main__':
    sys.exit(main())
