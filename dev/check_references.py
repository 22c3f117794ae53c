"""Every cross-reference of the package's docstrings and the docs names
something that exists.

    python dev/check_references.py

Sphinx roles (``:mod:``, ``:func:``, ``:class:``, ``:data:``, ``:meth:``,
``:attr:``) in the docstrings of ``wgse_mmseg``, ``wgse_bench``, ``tools/``
and ``dev/`` naming an object of the package, a relative name or a name of
the file's own module must resolve; the repository paths the docstrings and
the Markdown pages (README.md, docs/) mention (``tests/...``, ``tools/...``,
``dev/...``, ``docs/...``, ``configs/...``, ``wgse_mmseg/...``,
``wgse_bench/...``) must be there. Prints each broken one; the exit status
is 1 where there is one. ``bash tools/lint.sh`` runs it.
"""
import argparse
import ast
import glob
import importlib
import importlib.util
import os.path as osp
import re
import sys
from typing import Iterable, Iterator, List, Optional

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: a Sphinx role naming an object
ROLE = re.compile(r':(?:mod|func|class|data|meth|attr):`~?([A-Za-z_.][\w.]*)`')
#: a repository path (whole extensions: .csv is not .c)
PATH = re.compile(r'(?<![\w./-])((?:tests|tools|dev|docs|configs|'
                  r'wgse_mmseg|wgse_bench)/[\w./-]*\.(?:py|md|sh|c|json))'
                  r'(?![\w])')


def sources(root: str) -> List[str]:
    """The Python files whose docstrings are read."""
    return sorted(path for folder in ('wgse_mmseg', 'wgse_bench', 'tools',
                                      'dev')
                  for path in glob.glob(osp.join(root, folder, '**', '*.py'),
                                        recursive=True))


def pages(root: str) -> List[str]:
    """The Markdown pages whose repository paths are read."""
    return sorted(glob.glob(osp.join(root, 'docs', '*.md')) +
                  [osp.join(root, 'README.md')])


def _module_name(path: str, root: str) -> str:
    rel = osp.relpath(path, root)[:-3].replace(osp.sep, '.')
    return rel[:-len('.__init__')] if rel.endswith('.__init__') else rel


def _package(path: str, root: str) -> str:
    """The package a module's relative references start from."""
    module = _module_name(path, root)
    return module if path.endswith('__init__.py') else module.rpartition(
        '.')[0]


def _docstrings(path: str) -> Iterator[str]:
    tree = ast.parse(open(path, encoding='utf-8').read())
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                             ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node)
            if doc:
                yield doc


def _resolve(name: str, package: str):
    """Import the longest module prefix of ``name`` (relative names against
    ``package``) and walk the rest as attributes."""
    if name.startswith('.'):
        name = importlib.util.resolve_name(name, package)
    parts = name.split('.')
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module('.'.join(parts[:cut]))
        except ImportError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(name)


def _references(python_files, markdown_pages, root):
    """``(file, package, name, path)``: a role's target (``path`` None, or
    ``'local'`` for an undotted name of the file's own module) or a
    repository path (``name`` None)."""
    for path in python_files:
        package = _package(path, root)
        for doc in _docstrings(path):
            for name in ROLE.findall(doc):
                if name.startswith(('wgse_mmseg', 'wgse_bench', '.')):
                    yield path, package, name, None
                elif '.' not in name:  # a name of this module or its classes
                    yield path, _module_name(path, root), name, 'local'
            for ref in PATH.findall(doc):
                yield path, package, None, ref
    for path in markdown_pages:
        for ref in PATH.findall(open(path, encoding='utf-8').read()):
            yield path, None, None, ref


def broken_references(python_files: Iterable[str],
                      markdown_pages: Iterable[str], root: str) -> List[str]:
    """``'file: reference'`` for every reference of ``python_files``'
    docstrings and of ``markdown_pages`` that does not resolve or is not a
    path under ``root``, sorted. Resolving a name imports its module."""
    broken = []
    for path, package, name, ref in _references(python_files,
                                                markdown_pages, root):
        where = osp.relpath(path, root)
        if ref == 'local':
            module = importlib.import_module(package)
            owners = [module] + [v for v in vars(module).values()
                                 if isinstance(v, type)]
            if not any(hasattr(owner, name) for owner in owners):
                broken.append(f'{where}: {name}')
        elif name is not None:
            try:
                _resolve(name, package)
            except (ImportError, AttributeError):
                broken.append(f'{where}: {name}')
        elif not glob.glob(osp.join(root, ref.rstrip('.'))):
            broken.append(f'{where}: {ref}')
    return sorted(set(broken))


def build_parser() -> argparse.ArgumentParser:
    return argparse.ArgumentParser(description=__doc__.split('\n\n')[0])


def main(argv: Optional[List[str]] = None) -> int:
    build_parser().parse_args(argv)
    if ROOT not in sys.path:
        sys.path.insert(0, ROOT)  # the tools' and dev/'s own modules resolve
    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # the MMSeg layer's modules import
    broken = broken_references(sources(ROOT), pages(ROOT), ROOT)
    for reference in broken:
        print(f'broken reference: {reference}')
    return 1 if broken else 0


if __name__ == '__main__':
    sys.exit(main())
