"""The documentation site builds with warnings as errors, and shows only API
names.

``sphinx-build -W --keep-going`` over ``docs/`` (``docs/conf.py``): a link
between pages or to a heading that is not there, a name on the API pages
(``docs/api.rst``, ``docs/api_bench.rst``) that the package no longer has, a
docstring of an API object that Sphinx cannot read, a cross-reference in one
that names nothing, or one that names an internal name of the package (not
on the API pages: ``conf.py``'s ``_internal_reference``), fails the build,
with Sphinx's own message. Then every dotted name of the package that a
built page shows in code (``wgse_mmseg.x.y``, ``wgse_bench.x``) must be on
the API pages (Sphinx's inventory of them, ``objects.inv``): an object
there, a member of one, or a module holding some.
"""
import glob
import os.path as osp
import re
import subprocess
import sys
from html.parser import HTMLParser

import pytest

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))

for _requirement in ('sphinx', 'myst_parser', 'furo'):
    pytest.importorskip(_requirement,
                        reason='pip install -r requirements/docs.txt')

#: a dotted name of the package as a page shows it (paths, with ``/``, are
#: not names)
NAME = re.compile(r'(?<![\w/.-])((?:wgse_mmseg|wgse_bench)(?:\.[A-Za-z_]\w*)+)'
                  r'(?![\w/])')


class _CodeText(HTMLParser):
    """The text of every ``<code>`` element of a page."""

    def __init__(self):
        super().__init__()
        self.depth, self.texts = 0, []

    def handle_starttag(self, tag, attrs):
        if tag == 'code':
            self.depth += 1
            self.texts.append('')

    def handle_endtag(self, tag):
        if tag == 'code' and self.depth:
            self.depth -= 1

    def handle_data(self, data):
        if self.depth:
            self.texts[-1] += data


def shown_names(page_html: str):
    """The package's dotted names a page shows in code."""
    parser = _CodeText()
    parser.feed(page_html)
    return {name for text in parser.texts for name in NAME.findall(text)}


def not_api(names, api):
    """Those of ``names`` that are not an object of ``api`` (dotted names),
    a member of one, or a module holding one."""
    return sorted(name for name in names
                  if name not in api and name.rsplit('.', 1)[0] not in api
                  and not any(n.startswith(name + '.') for n in api))


@pytest.fixture(scope='module')
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp('docs')
    proc = subprocess.run(
        [sys.executable, '-m', 'sphinx', '-W', '--keep-going', '-q',
         '-b', 'html', '-d', str(out / 'doctrees'),
         osp.join(ROOT, 'docs'), str(out / 'html')],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    return proc, out / 'html'


@pytest.mark.long(17)
def test_the_docs_build_without_warnings(built):
    proc, html = built
    assert proc.returncode == 0, proc.stderr[-6000:]
    assert (html / 'api.html').is_file()
    assert (html / 'api_bench.html').is_file()


@pytest.mark.long(17)
def test_pages_show_only_api_names(built):
    from sphinx.util.inventory import InventoryFile
    _, html = built
    with open(html / 'objects.inv', 'rb') as f:
        inventory = InventoryFile.load(f, '', osp.join)
    api = {name for kind, entries in inventory.items()
           if kind.startswith('py:') for name in entries}
    assert 'wgse_mmseg.register_all_modules' in api
    assert 'wgse_bench.timing.time_calls' in api
    shown = {}
    for page in sorted(glob.glob(str(html / '**' / '*.html'),
                                 recursive=True)):
        name = osp.relpath(page, html)
        if name.startswith(('_', 'genindex', 'search', 'py-modindex')):
            continue
        wrong = not_api(shown_names(open(page, encoding='utf-8').read()),
                        api)
        if wrong:
            shown[name] = wrong
    assert not shown, f'pages show names not on the API pages: {shown}'


def test_the_check_finds_an_internal_name():
    """What the page check reads: code text, dotted names of the package
    but not paths; a constant of a documented module is not API."""
    page = ('<p><code class="docutils literal"><span>wgse_mmseg.fileio.'
            'spike_files.SPIKE_FORMATS</span></code> and <code>wgse_mmseg/'
            'fileio/spike_files.py</code>, <code>wgse_mmseg.fileio.'
            'spike_files.load_spikes()</code></p>')
    names = shown_names(page)
    assert names == {'wgse_mmseg.fileio.spike_files.SPIKE_FORMATS',
                     'wgse_mmseg.fileio.spike_files.load_spikes'}
    api = {'wgse_mmseg.fileio.spike_files.load_spikes', 'wgse_mmseg.core.WGSE'}
    assert not_api(names, api) == [
        'wgse_mmseg.fileio.spike_files.SPIKE_FORMATS']
    assert not_api({'wgse_mmseg.core', 'wgse_mmseg.core.WGSE.backend'},
                   api) == []
