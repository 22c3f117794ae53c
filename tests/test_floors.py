"""The house's floors: no import runs back up a floor, and the library never
imports the measurement wing (docs/architecture.md, "Floors").

Every ``import`` statement of every module of ``wgse_mmseg``, at module
level or inside a function, is read from the source (nothing is imported
here): a module may import its own package and the packages of the floors
below its own, never one above, and never ``wgse_bench``. The wing,
``wgse_bench``, imports the library as any user's script would.
"""
import ast
import glob
import importlib.util
import os.path as osp

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))

#: the library's packages (and top-level modules) from the ground floor up
FLOORS = (
    ('version', 'errors', 'limits', 'argument_checks', 'command_line'),
    ('core',),
    ('fileio',),
    ('data_generation',),
    ('compat',),
    ('_openmmlab',),
    ('utils',),
    ('datasets', 'evaluation', 'models'),
    ('engine',),
    ('apis',),
    ('mmseg_layer', '__init__'),
)
FLOOR = {name: level for level, names in enumerate(FLOORS) for name in names}


def _imports(path, package):
    """Every dotted name ``path``'s import statements name (``from a import
    b`` gives ``a`` and ``a.b``), relative names resolved in ``package``."""
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


def _library_modules():
    """``(path, package, floor name)`` of every module of ``wgse_mmseg``."""
    for path in sorted(glob.glob(osp.join(ROOT, 'wgse_mmseg', '**', '*.py'),
                                 recursive=True)):
        parts = osp.relpath(path, ROOT)[:-3].split(osp.sep)
        package = '.'.join(parts[:-1])
        yield path, package, parts[1]


def test_every_package_is_on_a_floor():
    unplaced = sorted({floor for _, _, floor in _library_modules()
                       if floor not in FLOOR})
    assert not unplaced, (f'put {unplaced} on a floor of FLOORS (what it '
                          f'imports decides which)')


def test_no_import_runs_up_a_floor_or_into_the_wing():
    wrong = []
    for path, package, floor in _library_modules():
        where = osp.relpath(path, ROOT)
        for line, name in _imports(path, package):
            top, _, rest = name.partition('.')
            if top == 'wgse_bench':
                wrong.append(f'{where}:{line}: imports the measurement wing '
                             f'({name})')
            elif top == 'wgse_mmseg' and rest:
                target = rest.split('.')[0]
                if FLOOR.get(target, 0) > FLOOR[floor]:
                    wrong.append(f'{where}:{line}: {floor} imports {name}, '
                                 f'a floor above it')
    assert not wrong, '\n'.join(wrong)


def test_the_check_sees_an_import_up_a_floor(tmp_path):
    """The reader above finds a deferred relative import (the kind that ran
    from ``utils`` up to ``engine``) and names its target."""
    module = tmp_path / 'distributed.py'
    module.write_text('def f():\n    from .. import engine\n')
    found = [name for _, name in _imports(str(module), 'wgse_mmseg.utils')]
    assert 'wgse_mmseg.engine' in found
