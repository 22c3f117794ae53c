"""Walking a folder tree (wgse_mmseg.fileio.folder_walk.files_under): random
trees of folders, files and links (to folders, ancestors, the folder
itself, files, nothing) against an independent reference built from
``os.path.realpath``; the loader of training images on a folder linking to
itself."""
import os
import os.path as osp

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from wgse_mmseg.fileio.folder_walk import files_under
from wgse_mmseg.data_generation.views import load_images


def _reachable_files(root, suffix=None):
    """The real paths of the regular files reachable from ``root``
    following links, each once."""
    seen, files, pending = set(), set(), [osp.realpath(root)]
    while pending:
        folder = pending.pop()
        if folder in seen:
            continue
        seen.add(folder)
        for name in os.listdir(folder):
            real = osp.realpath(osp.join(folder, name))
            if osp.isdir(real):
                pending.append(real)
            elif osp.isfile(real) and (suffix is None or
                                       name.endswith(suffix)):
                files.add(real)
    return files


#: a tree: each step makes a folder, a file or a link inside an existing
#: folder (chosen by index); a link points at an existing entry, a folder
#: above, or a missing name
STEPS = st.lists(st.tuples(
    st.sampled_from(['folder', 'file', 'link', 'loop', 'broken']),
    st.integers(0, 50), st.integers(0, 50)), max_size=25)


def _build(root, steps):
    folders, entries = [root], []
    for number, (kind, where, target) in enumerate(steps):
        parent = folders[where % len(folders)]
        path = osp.join(parent, f'{kind}{number}' + (
            '.png' if kind in ('file', 'link') else ''))
        if kind == 'folder':
            os.mkdir(path)
            folders.append(path)
        elif kind == 'file':
            with open(path, 'w') as f:
                f.write(str(number))
        elif kind == 'link' and entries:
            os.symlink(entries[target % len(entries)], path)
        elif kind == 'loop':  # a folder above it, or itself
            ancestors = [f for f in folders if parent.startswith(f)]
            os.symlink(ancestors[target % len(ancestors)], path)
        else:
            os.symlink(osp.join(root, 'missing'), path)
        entries.append(path)


@settings(max_examples=60, deadline=None)
@given(steps=STEPS)
def test_every_real_file_once_and_the_walk_ends(tmp_path_factory, steps):
    root = str(tmp_path_factory.mktemp('tree'))
    _build(root, steps)
    listed = files_under(root)
    assert listed == sorted(listed) == files_under(root)  # deterministic
    assert all(p.startswith(root + os.sep) for p in listed)
    real = [osp.realpath(p) for p in listed]
    assert len(set(real)) == len(real)  # each once
    assert set(real) == _reachable_files(root)
    pngs = files_under(root, ('.PNG', ))  # endings match in any case
    assert set(map(osp.realpath, pngs)) == _reachable_files(root, '.png')


def test_depth_keeps_one_level(tmp_path):
    for path in ('a.dat', 'city/b.dat', 'city/deeper/c.dat', 'city/d.txt'):
        os.makedirs(tmp_path / osp.dirname(path), exist_ok=True)
        (tmp_path / path).write_text(path)
    os.symlink('city', tmp_path / 'twin')  # the same city again
    os.symlink('a.dat', tmp_path / 'alias.dat')  # the same file again
    root = str(tmp_path)
    assert files_under(root, ('.dat', ), depth=1) == [
        osp.join(root, 'a.dat')]
    assert files_under(root, ('.dat', ), depth=2) == [
        osp.join(root, 'city', 'b.dat')]
    assert files_under(root, ('.dat', )) == [
        osp.join(root, 'a.dat'), osp.join(root, 'city', 'b.dat'),
        osp.join(root, 'city', 'deeper', 'c.dat')]
    assert files_under(str(tmp_path / 'missing')) == []


def test_the_image_loader_reads_each_image_once(tmp_path):
    """Two links to the folder itself (``l1 -> .``, ``l2 -> .``) and a link
    to an image: the loader ends, and reads each image once."""
    rng = np.random.default_rng(0)
    for name in ('a.png', 'b.jpg'):
        cv2.imwrite(str(tmp_path / name),
                    rng.integers(0, 255, (8, 8), np.uint8))
    os.symlink('.', tmp_path / 'l1')
    os.symlink('.', tmp_path / 'l2')
    os.symlink('a.png', tmp_path / 'c.png')
    paths, images = load_images(str(tmp_path), max_side=64)
    assert paths == [str(tmp_path / 'a.png'), str(tmp_path / 'b.jpg')]
    assert len(images) == 2
