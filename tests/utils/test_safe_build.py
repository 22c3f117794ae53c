"""Configs read from files build allow-listed classes only, at every depth;
and an audit of every registry build in the package."""
import ast
import os
import os.path as osp
import re

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from mmengine.registry import Registry

from wgse_mmseg.utils.config_data import ConfigDataError
from wgse_mmseg.utils.safe_build import (MAX_DEPTH, build_from_file_config,
                                         check_file_config)

ROOT = osp.dirname(osp.dirname(osp.dirname(osp.abspath(__file__))))


class Leaf:
    def __init__(self, size: int = 1, note=None):
        self.size, self.note = size, note


class Other:
    def __init__(self, size: int = 1):
        self.size = size


class Node:
    def __init__(self, child=None, extra=None, values=(), **kwargs):
        self.child, self.extra, self.values = child, extra, values
        self.kwargs = kwargs


ALLOWED = {Node: dict(child={Leaf: {}})}


def _error(cfg, allowed=ALLOWED):
    with pytest.raises(ConfigDataError) as info:
        check_file_config(cfg, allowed, 'file.pth', "meta['model']")
    return str(info.value)


def test_accepts_allowed_configs_and_returns_a_plain_copy():
    cfg = dict(type='Node', child=dict(type='Leaf', size=3,
                                       note=dict(a=[1, 2.5, None, 'x'])),
               extra=None, values=(1, (2, True)))
    checked = check_file_config(cfg, ALLOWED, 'f', 'k')
    assert checked == cfg and checked is not cfg
    assert checked['child']['note'] is not cfg['child']['note']
    assert check_file_config(dict(type='Node', child=None), ALLOWED, 'f',
                             'k') == dict(type='Node', child=None)


@pytest.mark.parametrize('cfg, path, words', [
    (dict(type='os.system', command='true'), "meta['model'].type",
     'dotted path'),
    (dict(type='Leaf'), "meta['model'].type", "allowed here: ['Node']"),
    (dict(type=Node), "meta['model'].type", 'not one of'),
    (dict(size=1), "meta['model'].type", 'None'),
    (dict(type='Node', _scope_='this'), "meta['model']._scope_",
     'imports a module'),
    (dict(type='Node', child=dict(type='Other')),
     "meta['model'].child.type", "allowed here: ['Leaf']"),
    (dict(type='Node', child=dict(type='Leaf', _scope_='mmseg')),
     "meta['model'].child._scope_", 'scope'),
    (dict(type='Node', child=dict(type='mmengine.model.BaseModel')),
     "meta['model'].child.type", 'dotted path'),
    (dict(type='Node', child=[dict(type='Leaf')]),
     "meta['model'].child", 'found a list'),
    # **kwargs is not followed: only named arguments
    (dict(type='Node', command='true'), "meta['model'].command",
     "takes no argument 'command'"),
    (dict(type='Node', child=dict(type='Leaf', colour=1)),
     "meta['model'].child.colour", "Leaf takes no argument"),
    # a config where the allow-list has none, at several depths
    (dict(type='Node', extra=dict(type='Leaf')), "meta['model'].extra.type",
     'no config is allowed'),
    (dict(type='Node', values=[1, dict(a=(dict(_scope_='this'), ))]),
     "meta['model'].values[1].a[0]._scope_", 'no config is allowed'),
    (dict(type='Node', child=dict(type='Leaf', note=dict(
        x=[dict(type='os.system', command='true')]))),
     "meta['model'].child.note.x[0].type", 'no config is allowed'),
    # not plain data
    (dict(type='Node', extra=print), "meta['model'].extra",
     'builtin_function_or_method is not plain data'),
    (dict(type='Node', extra=torch.zeros(2)), "meta['model'].extra",
     'Tensor is not plain data'),
    (dict(type='Node', extra={1: 2}), "meta['model'].extra",
     'key 1 is not a string'),
    ({'type': 'Node', 3: 4}, "meta['model']", 'key 3 is not a string'),
    ('Node', "meta['model']", 'found a str'),
])
def test_refusals_name_the_file_and_the_key(cfg, path, words):
    message = _error(cfg)
    assert message.startswith(f'file.pth: {path}: '), message
    assert words in message


def test_nesting_is_bounded():
    deep = []
    for _ in range(MAX_DEPTH + 5):
        deep = [deep]
    assert 'nested deeper' in _error(dict(type='Node', extra=deep))
    ok = []
    for _ in range(MAX_DEPTH - 1):
        ok = [ok]
    check_file_config(dict(type='Node', extra=ok), ALLOWED, 'f', 'k')


_plain = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) |
    st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(
        st.sampled_from(['a', 'b', 'type', '_scope_']), inner, max_size=3),
    max_leaves=10)


@settings(max_examples=60, deadline=None)
@given(note=_plain)
def test_a_data_argument_is_accepted_exactly_when_it_holds_no_config(note):
    """Reference: a hand-written search for a dict with ``type`` or
    ``_scope_`` anywhere in the value."""
    def holds_config(value):
        if isinstance(value, dict):
            return bool({'type', '_scope_'} & set(value)) or any(
                holds_config(v) for v in value.values())
        if isinstance(value, list):
            return any(holds_config(v) for v in value)
        return False
    cfg = dict(type='Node', child=dict(type='Leaf', note=note))
    if holds_config(note):
        assert "meta['model'].child.note" in _error(cfg)
    else:
        assert check_file_config(cfg, ALLOWED, 'f', 'k') == cfg


def test_build_gives_the_registry_classes_not_names(monkeypatch):
    """The registry builds the allowed classes themselves: no name from the
    file is ever looked up (``Registry.get`` is what imports dotted names)."""
    registry = Registry('test')
    registry.register_module(module=Node)
    registry.register_module(module=Leaf)
    looked_up = []
    monkeypatch.setattr(Registry, 'get',
                        lambda self, key: looked_up.append(key))
    built = build_from_file_config(
        registry, dict(type='Node', child=dict(type='Leaf', size=2)),
        ALLOWED, 'f', 'k')
    assert isinstance(built, Node) and built.child == dict(type=Leaf, size=2)
    assert looked_up == []


def test_loading_the_shipped_weights_looks_up_no_name(monkeypatch):
    """End to end: ``load_reconstructor`` builds the model, its enhancer and
    its data preprocessor without one registry lookup by name."""
    from wgse_mmseg.models.reconstruction import load_reconstructor
    looked_up = []
    original = Registry.get

    def get(self, key):
        looked_up.append(key)
        return original(self, key)
    monkeypatch.setattr(Registry, 'get', get)
    model = load_reconstructor()
    assert type(model.enhancer).__name__ == 'WGSE'
    assert looked_up == []


# ------------------------------------------------------------------ audit
#: calls that build objects from a config, choose code by name, or execute
#: config text
BUILD_CALL = re.compile(
    r'(\.build$|(^|\.)build_from_cfg$|Registry$|\.fromstring$|\.fromfile$|'
    r'from_cfg$|(^|\.)init_model$|(^|\.)Compose$|init_default_scope$|'
    r'import_module$|get_object_from_string$|^eval$|^exec$|^EFFECTS\[|'
    r'build_from_file_config$|Inferencer$)')

#: every such call in wgse_mmseg/ and tools/ (file, enclosing function,
#: callee), reviewed: where its config comes from
REVIEWED = {
    ('wgse_bench/model_bases.py', 'try_model_base', 'MODELS.build'):
        'MMSeg\'s own model bases, combined by spike_config',
    ('wgse_bench/model_bases.py', 'try_model_base', 'init_default_scope'):
        'MMSeg\'s own model bases',
    ('wgse_mmseg/utils/spike_model.py', 'spike_config', 'Config.fromfile'):
        'the user\'s config file and the package\'s dataset base (Python '
        'by design)',
    ('wgse_bench/segmentation.py', 'build_model', 'MODELS.build'):
        'the user\'s config file',
    ('wgse_mmseg/models/reconstruction.py', 'load_reconstructor',
     'build_from_file_config'):
        'a checkpoint: meta model/cfg, checked against RECONSTRUCTION_BUILDS',
    ('wgse_mmseg/utils/safe_build.py', 'build_from_file_config',
     'registry.build'):
        'the mechanism: types replaced by allow-listed classes',
    ('wgse_mmseg/models/reconstruction.py', 'SpikeReconstructor.__init__',
     'MODELS.build'):
        'its enhancer argument: from a config file, or from a checkpoint '
        'through build_from_file_config (then a class, not a name)',
    ('wgse_mmseg/models/data_preprocessor.py',
     'SpikeSegDataPreProcessor.__init__', 'MODELS.build'):
        'its enhancer argument, from the user\'s config file',
    ('wgse_bench/segmentation.py', 'validation_cost', 'DATASETS.build'):
        'the user\'s config file',
    ('wgse_bench/segmentation.py', 'validation_cost',
     'init_default_scope'):
        'the user\'s config file',
    ('wgse_mmseg/apis/inferencer.py', 'SpikeSegInferencer._init_pipeline',
     'Compose'):
        'the test pipeline of the user\'s config (a config is required: '
        'SpikeSegInferencer._init_model refuses a checkpoint\'s config text)',
    ('wgse_bench/experiments/grid.py', 'load_grid',
     'Config.fromfile'):
        'the user\'s grid config file (Python by design)',
    ('wgse_mmseg/utils/config.py', 'load_config', 'Config.fromfile'):
        'the user\'s config file (Python by design)',
    ('wgse_mmseg/utils/config.py', 'build_runner', 'RUNNERS.build'):
        'the user\'s config file; SpikeRunner refuses a checkpoint\'s '
        'meta[\'config\'] text that mmengine\'s resume would execute',
    ('wgse_mmseg/utils/config.py', 'build_runner', 'Runner.from_cfg'):
        'the user\'s config file',
    ('wgse_mmseg/engine/runner.py', 'SpikeRunner.from_cfg',
     'super().from_cfg'):
        'the user\'s config file',
    ('wgse_mmseg/core/simulation/scene.py', 'parse_effects', 'EFFECTS[name]'):
        'a scene file: names looked up in the simulator\'s own effect '
        'table (unknown names refused first), parameters checked against '
        'each effect\'s declared defaults',
    ('wgse_mmseg/__init__.py', 'register_all_modules',
     'importlib.import_module'):
        'a fixed list of the package\'s modules',
    ('wgse_mmseg/core/__init__.py', '__getattr__',
     'importlib.import_module'):
        'the fixed _NAMES table of wgse_mmseg.core\'s own modules',
    ('wgse_mmseg/compat/checkpoint_safety.py', '_resolve',
     'importlib.import_module'):
        'the fixed MMENGINE_CHECKPOINT_GLOBALS',
    ('dev/check_references.py', '_resolve', 'importlib.import_module'):
        'a name of the package that a docstring of the checkout references',
    ('dev/check_references.py', 'broken_references',
     'importlib.import_module'):
        'the module of a file of the checkout',
    ('dev/check_api.py', '_modules', 'importlib.import_module'):
        'the modules of the package, as pkgutil walks them',
    ('dev/check_api.py', 'api_problems', 'importlib.import_module'):
        'the package, and the modules its API page names',
    ('tools/demo.py', 'build_pipeline', 'Compose'):
        'the test pipeline of the user\'s config file',
    ('tools/demo.py', 'main', 'init_default_scope'):
        'the user\'s config file',
    ('wgse_mmseg/apis/segmentor_checkpoint.py', 'load_segmentor',
     'MODELS.build'):
        'the user\'s config file; the checkpoint gives weights (read '
        'weights-only, loaded strictly) and its dataset meta as data',
    ('tools/deployment/pytorch2onnx.py', 'main', 'init_default_scope'):
        'the user\'s config file',
    ('wgse_bench/deployment.py', '_measure',
     'MODELS.build'):
        'the user\'s grid and config files; random weights',
    ('wgse_bench/deployment.py', '_measure',
     'init_default_scope'):
        'the user\'s config file',
}


def _build_calls():
    """``(file, enclosing function, callee)`` of every matching call."""
    found = set()
    for top in ('wgse_mmseg', 'wgse_bench', 'tools', 'dev'):
        for folder, _, names in os.walk(osp.join(ROOT, top)):
            for name in names:
                if not name.endswith('.py'):
                    continue
                path = osp.join(folder, name)
                with open(path) as f:
                    tree = ast.parse(f.read())
                found |= _calls_in(tree, osp.relpath(path, ROOT))
    return found


def _calls_in(tree: ast.AST, path: str):
    found, scope = set(), []

    def visit(node):
        named = isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef,
                                  ast.ClassDef))
        if named:
            scope.append(node.name)
        if isinstance(node, ast.Call):
            callee = ast.unparse(node.func)
            if BUILD_CALL.search(callee):
                found.add((path, '.'.join(scope) or '<module>', callee))
        for child in ast.iter_child_nodes(node):
            visit(child)
        if named:
            scope.pop()
    visit(tree)
    return found


def test_every_build_in_the_package_is_reviewed():
    """A new call that builds from a config (or looks code up by name) fails
    here until it is added to REVIEWED with where its config comes from;
    a config from a file must go through build_from_file_config."""
    found = _build_calls()
    unreviewed = sorted(found - set(REVIEWED))
    assert not unreviewed, (
        f'unreviewed builds {unreviewed}: if any takes data from a file, '
        f'build it with wgse_mmseg.utils.safe_build.build_from_file_config; '
        f'then add it to REVIEWED')
    assert not sorted(set(REVIEWED) - found), 'stale REVIEWED entries'


def test_the_audit_sees_builds():
    """The scanner itself: it finds builds however they are spelled, in
    classes and nested functions, and ignores text in strings."""
    tree = ast.parse(
        'class A:\n'
        '    def f(self):\n'
        '        def g():\n'
        '            return MODELS.build(cfg)\n'
        '        x = "MODELS.build(cfg)"\n'
        '        return mmengine.registry.build_from_cfg(c, R), eval(s)\n'
        'Config.fromstring(text, ".py")\n'
        'json.load(f)\n')
    assert _calls_in(tree, 'x.py') == {
        ('x.py', 'A.f.g', 'MODELS.build'),
        ('x.py', 'A.f', 'mmengine.registry.build_from_cfg'),
        ('x.py', 'A.f', 'eval'),
        ('x.py', '<module>', 'Config.fromstring')}
