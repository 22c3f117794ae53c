"""Sphinx configuration of the documentation site (``docs/``).

Built with warnings as errors (``sphinx-build -W --keep-going docs
<out>``, run by ``tests/test_docs.py``): a broken link between pages, a
stale name on the API page or a docstring Sphinx cannot read fails the
build. The guides are the Markdown files beside this one (myst-parser);
the API reference (``api.rst``) is generated from the docstrings.
"""
import importlib
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import wgse_mmseg  # noqa: E402

# autodoc imports the MMSeg layer's modules, which need the layer set up
# first, as every entry point does
wgse_mmseg.register_all_modules()

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


def _existing(target: str, scopes):
    """The object ``target`` names, read as Python would from one of
    ``scopes`` (dotted names of modules, classes, functions) or one of their
    packages; ``None`` where it names nothing."""
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
            return obj
    return None


def _internal_reference(app, env, node, contnode):
    """A reference to an internal name of the package (not on the API page)
    reads as its text, unlinked; one that names nothing stays missing, so
    that ``nitpicky`` fails the build on it. Names resolve from the
    documented object's own module (``docstring of <name>``) or from the
    page's current module and class."""
    if node.get('refdomain') != 'py':
        return None
    target = node['reftarget'].lstrip('.~')
    module, cls = node.get('py:module') or '', node.get('py:class') or ''
    scopes = [f'{module}.{cls}' if cls else module]
    documented = re.search(r'docstring of ([\w.]+)', node.source or '')
    if documented:
        scopes.insert(0, documented.group(1))
    ours = ('wgse_mmseg', 'wgse_bench')
    if not any(scope.startswith(ours) for scope in scopes) and \
            not target.startswith(ours):
        return None
    return contnode if _existing(target, scopes) is not None else None


def setup(app):
    app.connect('missing-reference', _internal_reference)
