"""Output folders that hold only what the package wrote, reached without
following a link out of them.

No link followed out of the folder
    Paths inside the folder are reached through :meth:`OwnedFolder.folder`
    and :meth:`OwnedFolder.file`: a folder on the way that is a symbolic
    link is refused (it could send writes anywhere), and what lies at a
    file's own path, when it is a link or no regular file (a FIFO, a
    socket), is removed, never its target, so it is neither read nor
    written through. Files are written by rename
    (:func:`~wgse_mmseg.fileio.atomic.atomic_output`), which replaces a path,
    never writes through it; a state file appended to in place is opened
    by :func:`open_append`, which refuses a link or a file with other
    names. A folder the package names itself (``<video>.partial``) is
    owned with ``named=True``: a link or file at its path is refused,
    never followed or removed.Only what the package wrote
    A folder a tool writes as its output is claimed
    (:func:`~wgse_mmseg.fileio.locks.own_folder`): the package makes it, or
    takes an empty one, and keeps in it the manifest :data:`MANIFEST_NAME`, the
    record of every file written there by rename while it is held
    (:func:`note_written`). An existing folder with other files and no manifest
    is refused before any work, naming some of them, and so is one that holds
    an input of the run at any depth (:func:`check_output_folder`: compared by
    device and inode, walking up each input's real parents, links resolved).
    Removal (:meth:`OwnedFolder.clear`, :meth:`OwnedFolder.remove`) takes only
    the files the manifest lists, and a folder only once it is empty: a file
    the user added is kept, and nothing is removed as a tree. A lock taken in a
    folder the package does not own (beside an ONNX file, in a training's work
    dir, which holds the checkpoint it resumes from) claims nothing
    (``claim=False``).
State verified before use
    What a tool finds in its folder is checked before it is trusted (a
    frame against the size and SHA-256 its writer recorded, a sample
    against its marker, an image against what it is made from), and what
    does not verify is made again: resume state is rebuilt from what
    verifies, never a dead end.

Locks are :mod:`.locks`', the input guard :mod:`.input_guard`'s.
"""
import contextlib
import json
import os
import os.path as osp
import stat
import sys
from typing import BinaryIO, Iterable, Iterator, List, Optional, Set

from .input_guard import (NOTED_INPUTS, OutputFolderError, check_output,
                          check_output_kind, file_identity, real_parents)

__all__ = []


#: the lock file of a folder's (only) job; ``.lock-<job>`` for a named one
LOCK_NAME = '.lock'


#: the manifest of a folder the package made: its first line
#: :data:`MANIFEST_HEADER`, then one JSON string a line, the path (relative
#: to the folder) of each file written there
MANIFEST_NAME = '.wgse-output'


MANIFEST_HEADER = b'wgse_mmseg output folder; files it wrote, one a line\n'


#: how many names of foreign files a refusal lists
_NAMES_SHOWN = 3


NOFOLLOW = getattr(os, 'O_NOFOLLOW', 0)


def check_output_folder(folder, inputs: Iterable = ()) -> None:
    """Refuse, before any work, the output folder ``folder`` where it is
    not one the package may write: anything but a folder at its path, a
    folder with files and no manifest (:data:`MANIFEST_NAME`: not made by
    the package), or one holding, at any depth, an input (one of
    ``inputs`` or a file the running tool read:
    :func:`~wgse_mmseg.fileio.input_guard.note_input`), compared by device and
    inode. A missing ``folder`` passes.

    Raises:
        OutputFolderError: naming the folder and what is wrong.
    """
    folder = os.fspath(folder)
    identity = file_identity(folder)
    if identity is None:
        return
    if not osp.isdir(folder):
        raise OutputFolderError(f'{folder}: not a folder, where the output '
                                f'folder goes; move it away')
    given = [os.fspath(path) for path in inputs] + list(NOTED_INPUTS.values())
    for source in given:
        if identity == file_identity(source) or identity in real_parents(
                source):
            raise OutputFolderError(
                f'{folder}: this output folder holds the input {source}; '
                f'what an output folder holds may be replaced or removed: '
                f'write the output elsewhere')
    if osp.lexists(osp.join(folder, MANIFEST_NAME)):
        return
    foreign = sorted(name for name in os.listdir(folder)
                     if not name.startswith(LOCK_NAME))
    if foreign:
        shown = ', '.join(foreign[:_NAMES_SHOWN]) + (
            f' and {len(foreign) - _NAMES_SHOWN} more'
            if len(foreign) > _NAMES_SHOWN else '')
        raise OutputFolderError(
            f'{folder}: an existing folder this package did not make '
            f'(it holds {shown}, and no {MANIFEST_NAME}); an output folder '
            f'holds only what the package writes: give a new or empty '
            f'folder')


def _paths_in(value) -> Iterator[str]:
    """The strings and paths in an argument value (a list's items too)."""
    if isinstance(value, (str, os.PathLike)):
        yield os.fspath(value)
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from _paths_in(item)


def check_tool_outputs(args, *outputs: str,
                       folders: Iterable[str] = ()) -> None:
    """A tool's output arguments (the names of ``args``' attributes, unset
    ones skipped) against every other argument that names an existing
    file or folder, before any work: :func:`check_output`, so an output
    given as one of the tool's inputs is refused naming both. Those named
    in ``folders`` are output folders (:func:`check_output_folder`); the
    others, files, are checked by :func:`check_output_kind` where they are
    not folders (some tools take a folder or a file)."""
    folders = tuple(folders)
    values = vars(args)
    inputs = [path for name, value in values.items()
              if name not in outputs + folders
              for path in _paths_in(value) if osp.exists(path)]
    for name in outputs + folders:
        for path in _paths_in(values.get(name)):
            check_output(path, inputs)
            if name in folders:
                check_output_folder(path, inputs)
            elif not osp.isdir(path):
                check_output_kind(path)


def unshare(path: str) -> None:
    """Before a library writes ``path`` in place (``open(path, 'w')``,
    which truncates what it finds and follows links): remove what lies
    there when it is a link or a file with other names (hard links), never
    its target, so the write makes a new file and the other names keep
    their content. A regular file of one name is left to be rewritten."""
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISLNK(info.st_mode) or (stat.S_ISREG(info.st_mode) and
                                      info.st_nlink > 1):
        discard(path)


def discard(path: str) -> None:
    """Remove what lies at ``path`` without following a link: a file, a
    link (never its target) or a FIFO; nothing when nothing is there. An
    input of this process (:func:`check_output`) and a folder (never
    removed as a tree: :meth:`OwnedFolder.remove`) are refused."""
    if not osp.islink(path):
        check_output(path)
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    if stat.S_ISDIR(mode):
        raise OutputFolderError(f'{path}: a folder where the package '
                                f'removes a file of its own; move it away')
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)


#: the claimed folders this process holds
#: (:func:`~wgse_mmseg.fileio.locks.own_folder`), the innermost last
HELD_FOLDERS: List['OwnedFolder'] = []


def note_written(path: str) -> None:
    """Record ``path``, a file just written, in the manifest of the
    innermost claimed folder this process holds that contains it (none:
    nothing), so that the folder's removal takes it
    (:meth:`OwnedFolder.clear`)."""
    real = osp.join(osp.realpath(osp.dirname(osp.abspath(path))),
                    osp.basename(path))
    for owned in reversed(HELD_FOLDERS):
        relative = osp.relpath(real, osp.realpath(owned.root))
        if relative != os.pardir and not relative.startswith(
                os.pardir + os.sep):
            owned.record(relative)
            return


def _open_own_file(path: str, flags: int, cannot: str,
                   not_regular: str) -> int:
    """``path`` opened with ``flags``, never through a link and never
    waiting on a FIFO, as a regular file of one name; else an
    :class:`OutputFolderError` ``'{path}: {cannot} (a link?): ...'`` or
    ``'{path}: {not_regular}'``."""
    try:
        fd = os.open(path, flags | NOFOLLOW | os.O_NONBLOCK, 0o666)
    except OSError as err:
        raise OutputFolderError(f'{path}: {cannot} (a link?): '
                                f'{err.strerror}') from err
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode) or info.st_nlink != 1:
        os.close(fd)
        raise OutputFolderError(f'{path}: {not_regular}')
    return fd


def open_manifest(path: str, flags: int) -> int:
    """The manifest ``path`` opened with ``flags``: a regular file of one
    name, never a link, or an :class:`OutputFolderError` naming it."""
    return _open_own_file(
        path, flags, 'cannot open the folder\'s manifest',
        'the folder\'s manifest is not a regular file of one name; move it '
        'away')


class OwnedFolder:
    """Paths inside a folder the package writes (its writer holds the
    lock: :func:`~wgse_mmseg.fileio.locks.own_folder`). ``lock``: its writer's
    lock file; ``claimed``: the folder is the package's, with a manifest of
    what it wrote (:data:`MANIFEST_NAME`), which :meth:`clear` and
    :meth:`remove`
    go by."""

    def __init__(self, root: str, lock: Optional[str] = None,
                 claimed: bool = False):
        #: the folder
        self.root = root
        self.claimed = claimed
        self._lock = lock
        self._manifest = osp.join(root, MANIFEST_NAME)

    def record(self, relative: str) -> None:
        """Add ``relative``, a file written in the folder, to its
        manifest (one ``O_APPEND`` write: writers of other jobs may append
        at the same time)."""
        fd = open_manifest(self._manifest, os.O_WRONLY | os.O_APPEND)
        try:
            os.write(fd, (json.dumps(relative) + '\n').encode())
        finally:
            os.close(fd)

    def written(self) -> Set[str]:
        """The paths (relative to the folder) its manifest lists; empty for
        a folder not claimed."""
        if not self.claimed or not osp.lexists(self._manifest):
            return set()
        fd = open_manifest(self._manifest, os.O_RDONLY)
        with os.fdopen(fd, 'rb') as f:
            lines = f.read().split(b'\n')[1:]
        names = set()
        for line in lines:
            with contextlib.suppress(ValueError):
                name = json.loads(line)
                if isinstance(name, str):
                    names.add(name)
        return names

    def discard_written(self, paths: Iterable[str]) -> List[str]:
        """Remove those of ``paths`` (inside the folder) that its manifest
        lists (:func:`discard`), leaving the others; the removed ones."""
        written = self.written()
        removed = []
        for path in paths:
            if osp.relpath(osp.join(osp.realpath(osp.dirname(
                    osp.abspath(path))), osp.basename(path)),
                    osp.realpath(self.root)) in written:
                discard(path)
                removed.append(path)
        return removed

    def clear(self) -> None:
        """Remove the files the package wrote in the folder, as its
        manifest lists them (each checked: :func:`discard`), and the
        folders inside that this leaves empty; files it did not write stay
        (a state that cannot be trusted, started over)."""
        root = osp.realpath(self.root)
        for relative in sorted(self.written(), reverse=True):
            path = osp.normpath(osp.join(root, relative))
            if osp.dirname(path) == path or not path.startswith(
                    root + os.sep) or osp.realpath(
                        osp.dirname(path)) != osp.dirname(path):
                continue  # a listed name that leads out (or via a link)
            with contextlib.suppress(OutputFolderError):
                discard(path)
            parent = osp.dirname(path)
            while parent != root:
                try:
                    os.rmdir(parent)
                except OSError:
                    break  # holds other files
                parent = osp.dirname(parent)
        if self.claimed:
            os.close(open_manifest(self._manifest,
                                   os.O_WRONLY | os.O_TRUNC))
            fd = open_manifest(self._manifest, os.O_WRONLY | os.O_APPEND)
            try:
                os.write(fd, MANIFEST_HEADER)
            finally:
                os.close(fd)

    def remove(self) -> None:
        """Remove the folder: the files it lists (:meth:`clear`), its
        manifest and lock, and the folder itself if that leaves it empty;
        else it stays, with a line on stderr naming what is in it."""
        self.clear()
        for path in (self._manifest, self._lock):
            if path is not None:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(path)
        try:
            os.rmdir(self.root)
        except OSError:
            left = sorted(os.listdir(self.root))
            print(f'{self.root}: kept: it holds files this package did not '
                  f'write ({", ".join(left[:_NAMES_SHOWN])}'
                  f'{" ..." if len(left) > _NAMES_SHOWN else ""})',
                  file=sys.stderr)

    def _inside(self, path: str) -> str:
        """``path`` relative to the root; it must lie inside it."""
        relative = osp.relpath(osp.abspath(path), osp.abspath(self.root))
        if relative == '.' or relative.startswith(os.pardir + os.sep) or \
                relative == os.pardir:
            raise OutputFolderError(f'{path}: not inside the output folder '
                                    f'{self.root}')
        return relative

    def folder(self, path: str) -> str:
        """``path``, a folder inside the root, made with every folder on
        the way; a link or a file on the way is an
        :class:`OutputFolderError` naming it."""
        current = self.root
        for part in self._inside(path).split(os.sep):
            current = osp.join(current, part)
            try:
                mode = os.lstat(current).st_mode
            except FileNotFoundError:
                with contextlib.suppress(FileExistsError):
                    os.mkdir(current)
                mode = os.lstat(current).st_mode
            if stat.S_ISLNK(mode):
                raise OutputFolderError(
                    f'{current}: a symbolic link inside the output folder '
                    f'{self.root}; writes are not sent through links (they '
                    f'could land anywhere): make it a folder, or write to '
                    f'an output folder on that disk')
            if not stat.S_ISDIR(mode):
                raise OutputFolderError(
                    f'{current}: a file where the output folder '
                    f'{self.root} needs a folder; move it away')
        return path

    def file(self, path: str) -> str:
        """``path``, a file inside the root, its folder made
        (:meth:`folder`), and what lies at it removed when it is a link or
        no regular file: afterwards it is absent or a regular file, safe
        to read or replace. A folder there is an
        :class:`OutputFolderError` naming it."""
        parent = osp.dirname(self._inside(path))
        if parent:
            self.folder(osp.join(self.root, parent))
        try:
            mode = os.lstat(path).st_mode
        except FileNotFoundError:
            return path
        if stat.S_ISDIR(mode):
            raise OutputFolderError(f'{path}: a folder where the output '
                                    f'folder {self.root} needs a file; '
                                    f'move it away')
        if not stat.S_ISREG(mode):
            discard(path)
        return path


def open_append(path: str) -> BinaryIO:
    """Open the state file ``path`` for appending: made if missing; a link
    (never followed), a file with other names (hard links) or anything but
    a regular file is an :class:`OutputFolderError` naming it."""
    fd = _open_own_file(
        path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 'cannot append to it',
        'not a regular file of one name; a state file is not appended to '
        'through a link')
    return os.fdopen(fd, 'ab')
