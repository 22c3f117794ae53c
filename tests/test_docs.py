"""The documentation site builds with warnings as errors.

``sphinx-build -W --keep-going`` over ``docs/`` (``docs/conf.py``): a link
between pages or to a heading that is not there, a name on the API page
(``docs/api.rst``) that the package no longer has, a docstring of an API
object that Sphinx cannot read, or a cross-reference in one that names
nothing, fails here, with Sphinx's own message.
"""
import os.path as osp
import subprocess
import sys

import pytest

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))

for _requirement in ('sphinx', 'myst_parser', 'furo'):
    pytest.importorskip(_requirement,
                        reason='pip install -r requirements/docs.txt')


@pytest.mark.long(17)
def test_the_docs_build_without_warnings(tmp_path):
    proc = subprocess.run(
        [sys.executable, '-m', 'sphinx', '-W', '--keep-going', '-q',
         '-b', 'html', '-d', str(tmp_path / 'doctrees'),
         osp.join(ROOT, 'docs'), str(tmp_path / 'html')],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-6000:]
    assert (tmp_path / 'html' / 'api.html').is_file()
