"""Every cross-reference in the package's docstrings and the docs points at
something that exists: Sphinx roles (``:mod:``, ``:func:``, ``:class:``,
``:data:``, ``:meth:``) naming ``wgse_mmseg`` or ``wgse_bench`` objects
resolve, and the repository paths they mention (``tests/...``,
``tools/...``, ``dev/...``, ``docs/...``, ``configs/...``,
``wgse_mmseg/...``, ``wgse_bench/...``) are there."""
import ast
import glob
import importlib
import importlib.util
import os.path as osp
import re

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
ROLE = re.compile(r':(?:mod|func|class|data|meth|attr):`~?([A-Za-z_.][\w.]*)`')
PATH = re.compile(r'(?<![\w./-])((?:tests|tools|dev|docs|configs|'
                  r'wgse_mmseg|wgse_bench)/[\w./-]*\.(?:py|md|sh|c|json))'
                  r'(?![\w])')  # whole extensions: .csv is not .c
SOURCES = sorted(path for folder in ('wgse_mmseg', 'wgse_bench', 'tools',
                                     'dev')
                 for path in glob.glob(osp.join(ROOT, folder, '**', '*.py'),
                                       recursive=True))
DOCS = sorted(glob.glob(osp.join(ROOT, 'docs', '*.md')) +
              [osp.join(ROOT, 'README.md')])


def _module_name(path):
    rel = osp.relpath(path, ROOT)[:-3].replace(osp.sep, '.')
    return rel[:-len('.__init__')] if rel.endswith('.__init__') else rel


def _package(path):
    """The package a module's relative references start from."""
    module = _module_name(path)
    return module if path.endswith('__init__.py') else module.rpartition(
        '.')[0]


def _docstrings(path):
    tree = ast.parse(open(path, encoding='utf-8').read())
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                             ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node)
            if doc:
                yield doc


def _resolve(name, package):
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


def _references():
    for path in SOURCES:
        package = _package(path)
        for doc in _docstrings(path):
            for name in ROLE.findall(doc):
                if name.startswith(('wgse_mmseg', 'wgse_bench', '.')):
                    yield path, package, name, None
                elif '.' not in name:  # a name of this module or its classes
                    yield path, _module_name(path), name, 'local'

            for ref in PATH.findall(doc):
                yield path, package, None, ref
    for path in DOCS:
        for ref in PATH.findall(open(path, encoding='utf-8').read()):
            yield path, None, None, ref


def test_docstrings_and_docs_reference_what_exists():
    broken = []
    for path, package, name, ref in _references():
        where = osp.relpath(path, ROOT)
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
        elif not osp.exists(osp.join(ROOT, ref.rstrip('.'))) and \
                not glob.glob(osp.join(ROOT, ref.rstrip('.'))):
            broken.append(f'{where}: {ref}')
    assert not broken, 'broken references:\n' + '\n'.join(sorted(set(broken)))
