"""The documentation site builds with warnings as errors, and its pages
show only API names.

    python dev/check_docs.py

``sphinx-build -W --keep-going`` over ``docs/`` (``docs/conf.py``), afresh
into a temporary folder: a link between pages or to a heading that is not
there, a name on the API pages (``docs/api.rst``, ``docs/api_bench.rst``)
that the package no longer has, a docstring of an API object that Sphinx
cannot read, a cross-reference in one that names nothing, or one that
names an internal name of the package (``conf.py``'s
``_internal_reference``) fails the build, with Sphinx's own message. Then
every dotted name of the package that a built page shows in code
(``wgse_mmseg.x.y``, ``wgse_bench.x``) must be on the API pages (Sphinx's
inventory of them, ``objects.inv``): an object there, a member of one, or a
module holding some. The exit status is 1 where the build or a page
fails. ``bash tools/lint.sh`` runs it.
"""
import argparse
import glob
import os.path as osp
import re
import subprocess
import sys
import tempfile
from html.parser import HTMLParser
from typing import Iterable, List, Optional, Set

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: a dotted name of the package as a page shows it (paths, with ``/``, are
#: not names)
NAME = re.compile(r'(?<![\w/.-])((?:wgse_mmseg|wgse_bench)(?:\.[A-Za-z_]\w*)+)'
                  r'(?![\w/])')
#: names the inventory must hold (else it was read wrongly)
KNOWN = ('wgse_mmseg.register_all_modules', 'wgse_bench.timing.time_calls')


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


def shown_names(page_html: str) -> Set[str]:
    """The package's dotted names a page shows in code."""
    parser = _CodeText()
    parser.feed(page_html)
    return {name for text in parser.texts for name in NAME.findall(text)}


def not_api(names: Iterable[str], api: Set[str]) -> List[str]:
    """Those of ``names`` that are not an object of ``api`` (dotted names),
    a member of one, or a module holding one."""
    return sorted(name for name in names
                  if name not in api and name.rsplit('.', 1)[0] not in api
                  and not any(n.startswith(name + '.') for n in api))


def page_problems(html: str) -> List[str]:
    """The built site in folder ``html``: its API pages are there, and each
    page shows only names of its inventory (:func:`not_api`)."""
    from sphinx.util.inventory import InventoryFile
    problems = [f'{name} was not built'
                for name in ('api.html', 'api_bench.html')
                if not osp.isfile(osp.join(html, name))]
    with open(osp.join(html, 'objects.inv'), 'rb') as f:
        inventory = InventoryFile.load(f, '', osp.join)
    api = {name for kind, entries in inventory.items()
           if kind.startswith('py:') for name in entries}
    problems += [f'objects.inv lacks {name}' for name in KNOWN
                 if name not in api]
    for page in sorted(glob.glob(osp.join(html, '**', '*.html'),
                                 recursive=True)):
        name = osp.relpath(page, html)
        if name.startswith(('_', 'genindex', 'search', 'py-modindex')):
            continue
        wrong = not_api(shown_names(open(page, encoding='utf-8').read()),
                        api)
        if wrong:
            problems.append(f'{name} shows names not on the API pages: '
                            f'{", ".join(wrong)}')
    return problems


def build_parser() -> argparse.ArgumentParser:
    return argparse.ArgumentParser(description=__doc__.split('\n\n')[0])


def main(argv: Optional[List[str]] = None) -> int:
    build_parser().parse_args(argv)
    with tempfile.TemporaryDirectory(prefix='wgse_docs_') as out:
        build = subprocess.run(
            [sys.executable, '-m', 'sphinx', '-W', '--keep-going', '-q',
             '-b', 'html', '-d', osp.join(out, 'doctrees'),
             osp.join(ROOT, 'docs'), osp.join(out, 'html')], cwd=ROOT)
        if build.returncode != 0:
            print(f'sphinx-build failed (exit status {build.returncode})')
            return 1
        problems = page_problems(osp.join(out, 'html'))
    for problem in problems:
        print(problem)
    return 1 if problems else 0


if __name__ == '__main__':
    sys.exit(main())
