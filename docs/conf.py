"""Sphinx configuration of the documentation site (``docs/``).

Built with warnings as errors (``sphinx-build -W --keep-going docs
<out>``, run by ``dev/check_docs.py``): a broken link between pages, a
stale name on the API page or a docstring Sphinx cannot read fails the
build. The guides are the Markdown files beside this one (myst-parser);
the API reference (``api.rst``) is generated from the docstrings.
"""
import importlib
import inspect
import os
import re
import sys

from sphinx.util import logging

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import wgse_mmseg  # noqa: E402

# autodoc imports the MMSeg layer's modules, which need the layer set up
# first, as every entry point does
wgse_mmseg.register_all_modules()

_LOG = logging.getLogger(__name__)

project = 'wgse_mmseg'
author = 'wgse_mmseg contributors'
copyright = '2026, wgse_mmseg contributors'
release = version = wgse_mmseg.__version__

extensions = [
    'myst_parser',
    'sphinx.ext.autodoc',
    'sphinx.ext.autosummary',
    'sphinx.ext.napoleon',
]
source_suffix = {'.rst': 'restructuredtext', '.md': 'markdown'}
root_doc = 'index'
exclude_patterns = ['_build']

# guides: GitHub-style heading anchors (``simulator.md#speed``)
myst_heading_anchors = 4
myst_enable_extensions = ['colon_fence']

# API reference: signatures without the hints (the docstrings say what each
# argument holds, with its shape); members in source order
autodoc_typehints = 'none'
autodoc_member_order = 'bysource'
autodoc_default_options = {'members': False}
autosummary_generate = False
napoleon_google_docstring = True
napoleon_numpy_docstring = False

# every cross-reference must resolve (a stale name fails the build); names
# of other libraries are not documented here
nitpicky = True
nitpick_ignore_regex = [
    (r'py:.*', r'(torch|np|numpy|mmengine|mmseg|mmcv|cv2|onnx|onnxruntime|'
               r'triton|argparse|os|pathlib|typing|collections|dataclasses|'
               r'concurrent|multiprocessing|threading|enum|abc)(\..*)?'),
]

html_theme = 'furo'
html_title = f'wgse_mmseg {release}'


#: the packages whose names the API pages hold
OURS = ('wgse_mmseg', 'wgse_bench')


def _existing(target: str, scopes):
    """``(object, dotted name)`` of what ``target`` names, read as Python
    would from one of ``scopes`` (dotted names of modules, classes,
    functions) or one of their packages; ``None`` where it names nothing."""
    prefixes = []
    for scope in scopes:
        parts = scope.split('.')
        prefixes += ['.'.join(parts[:cut]) for cut in range(len(parts), 0, -1)]
    for prefix in prefixes + ['']:
        words = (f'{prefix}.{target}' if prefix else target).split('.')
        for cut in range(len(words), 0, -1):
            try:
                obj = importlib.import_module('.'.join(words[:cut]))
            except ImportError:
                continue
            try:
                for word in words[cut:]:
                    obj = getattr(obj, word)
            except AttributeError:
                break
            return obj, '.'.join(words)
    return None


def _home(obj, dotted: str) -> str:
    """Where ``obj`` is defined: a module's name, a class's or function's
    module and qualified name, else the name it was reached by."""
    if inspect.ismodule(obj):
        return obj.__name__
    module = getattr(obj, '__module__', None)
    qualname = getattr(obj, '__qualname__', None)
    if isinstance(module, str) and isinstance(qualname, str):
        return f'{module}.{qualname}'
    return dotted


def _api_ids(env) -> set:
    """``id`` of every object the API pages document (and of the classes
    whose members count as theirs), computed once a build."""
    if not hasattr(env, 'wgse_api_ids'):
        ids = set()
        for name in env.get_domain('py').objects:
            found = _existing(name, [])
            if found is not None:
                ids.add(id(found[0]))
        env.wgse_api_ids = ids
    return env.wgse_api_ids


def _on_the_api_pages(obj, env) -> bool:
    """``obj`` is documented there, or is a member of a class that is."""
    ids = _api_ids(env)
    if id(obj) in ids:
        return True
    if inspect.ismodule(obj):  # a module the API pages document names of
        return any(name.startswith(obj.__name__ + '.')
                   for name in env.get_domain('py').objects)
    qualname = getattr(obj, '__qualname__', '')
    module = getattr(obj, '__module__', None)
    if isinstance(qualname, str) and '.' in qualname and module:
        owner = _existing(qualname.rsplit('.', 1)[0], [module])
        return owner is not None and id(owner[0]) in ids
    return False


def _internal_reference(app, env, node, contnode):
    """A reference that Sphinx cannot link. One to another library's name
    reads as its text, unlinked; one that names nothing stays missing, so
    that ``nitpicky`` fails the build on it; one to a name of this package
    that the API pages do not hold (an internal name) is a warning, so the
    build (warnings as errors) fails on it too: docs show only API names.
    Names resolve from the documented object's own module (``docstring of
    <name>``) or from the page's current module and class."""
    if node.get('refdomain') != 'py':
        return None
    target = node['reftarget'].lstrip('.~')
    module, cls = node.get('py:module') or '', node.get('py:class') or ''
    scopes = [f'{module}.{cls}' if cls else module]
    documented = re.search(r'docstring of ([\w.]+)', node.source or '')
    if documented:
        scopes.insert(0, documented.group(1))
    if not any(scope.startswith(OURS) for scope in scopes) and \
            not target.startswith(OURS):
        return None
    found = _existing(target, scopes)
    if found is None:
        return None
    obj, dotted = found
    home = _home(obj, dotted)
    if home.startswith(OURS) and not _on_the_api_pages(obj, env):
        _LOG.warning('names %s (%s), which is not on the API pages '
                     '(docs/api.rst, docs/api_bench.rst): say it in words, '
                     'or name an API object', target, home,
                     location=node, type='wgse', subtype='internal')
    return contnode


def setup(app):
    app.connect('missing-reference', _internal_reference)
