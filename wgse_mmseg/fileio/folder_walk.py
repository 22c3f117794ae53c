"""Listing the files of a folder tree: every walk ends, every file once.

:func:`files_under` is the package's one way to list the files a reader
takes from a folder (the images of a training folder, the samples of a
dataset, the inputs of a converter). Links are followed, since datasets are
often assembled from links, but each real folder is entered once and each
real file listed once (identified by device and inode), so a folder holding
links to itself (``l1 -> .``, ``l2 -> .``) or to an ancestor is walked to
its end, and a file reachable by several paths is read once, under the
first of them in the walk's order. The walk visits names in sorted order
and the listing is sorted, so the same tree always gives the same list.
A broken link is skipped. Needs no OpenMMLab.
"""
import os
import os.path as osp
import stat
from typing import List, Optional, Sequence, Set, Tuple

__all__ = []


def files_under(folder: str, suffixes: Optional[Sequence[str]] = None,
                depth: Optional[int] = None) -> List[str]:
    """The files under ``folder`` whose name ends with one of ``suffixes``
    (case-insensitive; ``None``: every file), each real file once, as
    paths starting with ``folder``, sorted; none when ``folder`` is no
    folder (the caller names what it expected there).

    Args:
        folder: the folder to walk (a link to one is followed).
        suffixes: the name endings to keep, e.g. ``('.png', '.jpg')``.
        depth: only the files exactly this many levels down (``1``: the
            folder's own files, ``2``: those of its sub-folders); ``None``:
            at any depth.

    Raises:
        OSError: naming a folder of the tree that cannot be listed.
    """
    if not osp.isdir(folder):
        return []
    endings = None if suffixes is None else tuple(s.lower() for s in suffixes)
    entered: Set[Tuple[int, int]] = set()
    listed: Set[Tuple[int, int]] = set()
    found: List[str] = []
    pending = [(os.fspath(folder), 1)]
    while pending:
        current, level = pending.pop()
        info = os.stat(current)
        if (info.st_dev, info.st_ino) in entered:
            continue  # reached again through a link: a loop, or a twin
        entered.add((info.st_dev, info.st_ino))
        subfolders = []
        for name in sorted(os.listdir(current)):
            path = osp.join(current, name)
            try:
                info = os.stat(path)  # follows a link
            except OSError:
                continue  # a broken link, or one looping on itself
            if stat.S_ISDIR(info.st_mode):
                if depth is None or level < depth:
                    subfolders.append((path, level + 1))
            elif (stat.S_ISREG(info.st_mode)
                  and (depth is None or level == depth)
                  and (endings is None or name.lower().endswith(endings))
                  and (info.st_dev, info.st_ino) not in listed):
                listed.add((info.st_dev, info.st_ino))
                found.append(path)
        pending.extend(reversed(subfolders))  # visited in sorted order
    return sorted(found)
