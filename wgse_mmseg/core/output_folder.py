"""The package owns its output folders: one writer, no link followed out.

Every tool that writes an output a re-run may resume (a walk's state
folder, a conversion, the synthetic dataset, the training images, the ONNX
export, a training's work dir) writes it inside :func:`own_folder`:

One writer at a time
    The folder's lock file ``<folder>/.lock`` (``.lock-<job>`` for one job
    of several that may share a folder: a shard of a conversion, one file
    of an export) is locked exclusively (``fcntl.flock``) for as long as
    the output is written, and records its writer: process id, host,
    command and start time. A second writer of the same output is refused
    at once with an :class:`OutputFolderError` naming the first, or, with
    ``wait=True`` (the tools' ``--wait``), waits for it to finish. The
    kernel releases the lock of a killed process, so a lock is never stale;
    the lock file is removed when its writer is done.
No link followed out of the folder
    Paths inside the folder are reached through :meth:`OwnedFolder.folder`
    and :meth:`OwnedFolder.file`: a folder on the way that is a symbolic
    link is refused (it could send writes anywhere), and what lies at a
    file's own path, when it is a link or no regular file (a FIFO, a
    socket), is removed, never its target, so it is neither read nor
    written through. Files are written by rename
    (:func:`~wgse_mmseg.core.io.atomic_output`), which replaces a path,
    never writes through it; a state file appended to in place is opened
    by :func:`open_append`, which refuses a link or a file with other
    names. A folder the package names itself (``<video>.partial``) is
    owned with ``named=True``: a link or file at its path is refused,
    never followed or removed.
Only what the package wrote
    A folder a tool writes as its output is claimed (:func:`own_folder`):
    the package makes it, or takes an empty one, and keeps in it the
    manifest :data:`MANIFEST_NAME`, the record of every file written there
    by rename while it is held (:func:`note_written`). An existing folder
    with other files and no manifest is refused before any work, naming
    some of them, and so is one that holds an input of the run at any
    depth (:func:`check_output_folder`: compared by device and inode,
    walking up each input's real parents, links resolved). Removal
    (:meth:`OwnedFolder.clear`, :meth:`OwnedFolder.remove`) takes only the
    files the manifest lists, and a folder only once it is empty: a file
    the user added is kept, and nothing is removed as a tree. A lock taken
    in a folder the package does not own (beside an ONNX file, in a
    training's work dir, which holds the checkpoint it resumes from)
    claims nothing (``claim=False``).
Outputs are files, or streamed to
    An output path where a FIFO or a character device already lies
    (``/dev/null``, a shell's ``>(cat)``) is written through, never
    replaced by a regular file (:func:`~wgse_mmseg.core.io.atomic_path`);
    a socket, a block device or a folder where a file goes is refused
    naming it, by the tools before any work (:func:`check_tool_outputs`,
    :func:`check_output_kind`).
No input replaced
    While a tool runs (its ``main`` is wrapped by :func:`keeps_inputs`),
    every file the package reads as input (a spike file, an image, a
    config, a checkpoint, an ONNX model) is noted (:func:`note_input`) by
    its device and inode, so hard links and symbolic links are the same
    file; every output the package writes
    (:func:`~wgse_mmseg.core.io.atomic_path`) and every path it removes
    (:func:`discard`) is checked
    against them (:func:`check_output`): an output over an input is an
    :class:`OutputFolderError` naming both, and nothing is written. Tools
    also check their output arguments against their other arguments
    before any work (:func:`check_tool_outputs`). (A library caller may
    read a file and save it back; only a tool's run is guarded.) A lock or
    state file the package writes in place is one it made: a file with other
    names (a hard link) or content that is not its record is refused, never
    truncated.
State verified before use
    What a tool finds in its folder is checked before it is trusted (a
    frame against the size and SHA-256 its writer recorded, a sample
    against its marker, an image against what it is made from), and what
    does not verify is made again: resume state is rebuilt from what
    verifies, never a dead end.

Needs no OpenMMLab.
"""
import contextlib
import datetime
import fcntl
import functools
import hashlib
import json
import os
import os.path as osp
import socket
import stat
import sys
import time
from typing import (BinaryIO, Callable, Dict, Iterable, Iterator, List,
                    Optional, Set, Tuple)

from .limits import cut, parse_json

__all__ = ['OutputFolderError']

#: the lock file of a folder's (only) job; ``.lock-<job>`` for a named one
LOCK_NAME = '.lock'
#: the manifest of a folder the package made: its first line
#: :data:`MANIFEST_HEADER`, then one JSON string a line, the path (relative
#: to the folder) of each file written there
MANIFEST_NAME = '.wgse-output'
MANIFEST_HEADER = b'wgse_mmseg output folder; files it wrote, one a line\n'
#: how many names of foreign files a refusal lists
_NAMES_SHOWN = 3
_NOFOLLOW = getattr(os, 'O_NOFOLLOW', 0)


class OutputFolderError(ValueError):
    """An output folder this package cannot own as asked: another process
    writes it, or a path in it is a link or not what it must be; names the
    path."""


def _lock_path(folder: str, job: Optional[str]) -> str:
    if job is None:
        return osp.join(folder, LOCK_NAME)
    name = ''.join(c if c.isalnum() or c in '._-' else '_' for c in job)
    if len(name) > 200:
        name = hashlib.sha256(job.encode()).hexdigest()
    return osp.join(folder, f'{LOCK_NAME}-{name}')


#: how long a refused writer waits for the lock holder's record (seconds)
RECORD_WAIT_S = 1.0


def _writer_record() -> bytes:
    """Who writes: process id, host, command and start time, as JSON."""
    return json.dumps(dict(
        pid=os.getpid(), host=socket.gethostname(),
        command=' '.join([osp.basename(sys.executable)] + sys.argv),
        started=datetime.datetime.now(datetime.timezone.utc).isoformat(
            timespec='seconds'))).encode()


def _describe_writer(fd: int) -> str:
    """The writer recorded in the lock file ``fd``, in words. A writer
    records itself just after it takes the lock, so an unreadable record
    is read again for up to :data:`RECORD_WAIT_S` before it is called
    unrecorded."""
    deadline = time.monotonic() + RECORD_WAIT_S
    while True:
        try:
            record = parse_json(os.pread(fd, 4096, 0).decode(),
                                'the lock file', 'writer record')
            return (f'process {int(record["pid"])} on host '
                    f'{cut(str(record["host"]), 100)}, started '
                    f'{cut(str(record["started"]), 40)}: '
                    f'{cut(str(record["command"]), 300)}')
        except (OSError, ValueError, TypeError, KeyError):
            if time.monotonic() > deadline:
                return 'a process that has not yet recorded itself'
            time.sleep(0.02)


#: ``(st_dev, st_ino)`` -> the path it was read by, of every file read as
#: an input while a tool runs (:func:`note_input`, :func:`keeps_inputs`)
_INPUTS: Dict[Tuple[int, int], str] = {}
#: how many :func:`keeps_inputs` runs are under way (nested: a tool's
#: ``main`` called by another)
_GUARDS = [0]


def keeps_inputs(main: Callable) -> Callable:
    """Decorate a tool's ``main``: while it runs, inputs are noted and no
    output replaces one (:func:`check_output`); an
    :class:`OutputFolderError` ends the tool with ``<tool>: error: <the
    message>`` (exit status 1); afterwards the notes are forgotten."""
    tool = osp.basename(main.__globals__.get('__file__') or main.__name__)

    @functools.wraps(main)
    def run(*args, **kwargs):
        _GUARDS[0] += 1
        try:
            return main(*args, **kwargs)
        except OutputFolderError as err:
            sys.exit(f'{tool}: error: {err}')
        finally:
            _GUARDS[0] -= 1
            if not _GUARDS[0]:
                _INPUTS.clear()
    return run


def _identity(path) -> Optional[Tuple[int, int]]:
    """``(st_dev, st_ino)`` of the file at ``path`` (links followed), or
    ``None`` where nothing (or nothing reachable) is there."""
    try:
        info = os.stat(path)
    except (OSError, ValueError):  # missing, a dangling link, a NUL byte
        return None
    return info.st_dev, info.st_ino


def note_input(path) -> None:
    """Note ``path``, a file read as an input while a tool runs
    (:func:`keeps_inputs`; elsewhere nothing): no output of the run
    replaces or removes it (:func:`check_output`)."""
    if not _GUARDS[0]:
        return
    identity = _identity(path)
    if identity is not None:
        _INPUTS.setdefault(identity, os.fspath(path))


def check_input_file(path: str, what: str, error: type = ValueError,
                     missing: Optional[type] = None) -> None:
    """Check that ``path``, about to be read as a ``what``, is a regular
    file (a FIFO or device would block or never end, a folder is none)
    and note it as an input (:func:`note_input`).

    Raises:
        ``missing`` (default ``error``): nothing at ``path``.
        ``error``: naming ``path``, for anything but a regular file.
    """
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise (missing or error)(f'{path}: no such {what}') from None
    if not stat.S_ISREG(mode):
        raise error(f'{path}: not a regular file (a FIFO, device or '
                    f'folder); a {what} is read from a file on disk')
    note_input(path)


def check_output(path, inputs: Iterable = ()) -> None:
    """Refuse to write (or remove) ``path`` where it is an input: a file
    the running tool read (:func:`note_input`) or one of ``inputs``, compared
    by device and inode (hard links and symbolic links included).

    Raises:
        OutputFolderError: naming the output and the input it is.
    """
    identity = _identity(path)
    if identity is None:
        return
    found = {_identity(given): os.fspath(given) for given in inputs}
    source = found.get(identity) or _INPUTS.get(identity)
    if source is not None:
        same = osp.abspath(source) == osp.abspath(os.fspath(path))
        raise OutputFolderError(
            f'{path}: this output is the input {source}'
            f'{"" if same else " (the same file by another name or link)"}'
            f'; an output never replaces an input: write it elsewhere')


def check_output_kind(path, streamed: bool = True) -> Optional[str]:
    """What lies at the output ``path`` (links followed): ``None`` where
    nothing or a regular file is there, ``'fifo'`` or ``'character
    device'`` where it is written through (``streamed``:
    :func:`~wgse_mmseg.core.io.atomic_path` does).

    Raises:
        OutputFolderError: naming ``path``, for a folder, a socket or a
            block device (never written, never replaced), or a FIFO or
            character device where the output cannot be streamed.
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    if stat.S_ISREG(mode):
        if _through_descriptor(path):
            raise OutputFolderError(
                f'{path}: names an open file of a process (a link through '
                f'/proc/.../fd/, as /dev/stdout redirected to a file); a '
                f'rename would replace the link: give the file\'s own path')
        return None
    kind = ('fifo' if stat.S_ISFIFO(mode) else 'character device'
            if stat.S_ISCHR(mode) else 'folder' if stat.S_ISDIR(mode)
            else 'socket' if stat.S_ISSOCK(mode) else 'block device'
            if stat.S_ISBLK(mode) else 'special file')
    if streamed and kind in ('fifo', 'character device'):
        return kind
    how = ('this output is written to a file, not streamed'
           if kind in ('fifo', 'character device') else
           'it is neither replaced nor written through')
    raise OutputFolderError(f'{path}: a {kind} where the output file goes; '
                            f'{how}: give the path of a file')


def _through_descriptor(path: str) -> bool:
    """Whether ``path``, or a folder on its way, is a link that leads
    through a process's open file descriptors (``/dev/stdout``,
    ``/dev/fd/N``: ``/proc/<pid>/fd/N``)."""
    current = osp.abspath(os.fspath(path))
    for _ in range(40):  # the kernel's own bound on a chain of links
        if current.startswith('/proc/') and '/fd/' in current:
            return True
        parent = osp.dirname(current)
        real_parent = osp.realpath(parent)
        if real_parent != parent:
            if real_parent.startswith('/proc/') and '/fd' in real_parent:
                return True
            current = osp.join(real_parent, osp.basename(current))
            continue
        if not osp.islink(current):
            return False
        current = osp.normpath(osp.join(parent, os.readlink(current)))
    return False


def _real_parents(path: str) -> Iterator[Tuple[int, int]]:
    """``(st_dev, st_ino)`` of every folder above ``path``'s real location
    (links resolved), nearest first, up to the root."""
    current = osp.realpath(path)
    while True:
        parent = osp.dirname(current)
        if parent == current:
            return
        identity = _identity(parent)
        if identity is not None:
            yield identity
        current = parent


def check_output_folder(folder, inputs: Iterable = ()) -> None:
    """Refuse, before any work, the output folder ``folder`` where it is
    not one the package may write: anything but a folder at its path, a
    folder with files and no manifest (:data:`MANIFEST_NAME`: not made by
    the package), or one holding, at any depth, an input (one of
    ``inputs`` or a file the running tool read: :func:`note_input`),
    compared by device and inode. A missing ``folder`` passes.

    Raises:
        OutputFolderError: naming the folder and what is wrong.
    """
    folder = os.fspath(folder)
    identity = _identity(folder)
    if identity is None:
        return
    if not osp.isdir(folder):
        raise OutputFolderError(f'{folder}: not a folder, where the output '
                                f'folder goes; move it away')
    given = [os.fspath(path) for path in inputs] + list(_INPUTS.values())
    for source in given:
        if identity == _identity(source) or identity in _real_parents(
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


#: the claimed folders this process holds (:func:`own_folder`), the
#: innermost last
_HELD: List['OwnedFolder'] = []


def note_written(path: str) -> None:
    """Record ``path``, a file just written, in the manifest of the
    innermost claimed folder this process holds that contains it (none:
    nothing), so that the folder's removal takes it
    (:meth:`OwnedFolder.clear`)."""
    real = osp.join(osp.realpath(osp.dirname(osp.abspath(path))),
                    osp.basename(path))
    for owned in reversed(_HELD):
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
        fd = os.open(path, flags | _NOFOLLOW | os.O_NONBLOCK, 0o666)
    except OSError as err:
        raise OutputFolderError(f'{path}: {cannot} (a link?): '
                                f'{err.strerror}') from err
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode) or info.st_nlink != 1:
        os.close(fd)
        raise OutputFolderError(f'{path}: {not_regular}')
    return fd


def _open_manifest(path: str, flags: int) -> int:
    """The manifest ``path`` opened with ``flags``: a regular file of one
    name, never a link, or an :class:`OutputFolderError` naming it."""
    return _open_own_file(
        path, flags, 'cannot open the folder\'s manifest',
        'the folder\'s manifest is not a regular file of one name; move it '
        'away')


class OwnedFolder:
    """Paths inside a folder the package writes (its writer holds the
    lock: :func:`own_folder`). ``lock``: its writer's lock file;
    ``claimed``: the folder is the package's, with a manifest of what it
    wrote (:data:`MANIFEST_NAME`), which :meth:`clear` and :meth:`remove`
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
        fd = _open_manifest(self._manifest, os.O_WRONLY | os.O_APPEND)
        try:
            os.write(fd, (json.dumps(relative) + '\n').encode())
        finally:
            os.close(fd)

    def written(self) -> Set[str]:
        """The paths (relative to the folder) its manifest lists; empty for
        a folder not claimed."""
        if not self.claimed or not osp.lexists(self._manifest):
            return set()
        fd = _open_manifest(self._manifest, os.O_RDONLY)
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
            os.close(_open_manifest(self._manifest,
                                    os.O_WRONLY | os.O_TRUNC))
            fd = _open_manifest(self._manifest, os.O_WRONLY | os.O_APPEND)
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


#: seconds between the lines a waiting writer prints (:func:`_wait_for`)
WAIT_REPORT_S = 60.0
#: seconds between a waiting writer's tries of the lock
WAIT_POLL_S = 0.2


def _wait_for(folder: str, fd: int) -> None:
    """Take the lock of ``fd``, held by another writer, when it is free;
    say on stderr whom it waits for when the wait starts and every
    :data:`WAIT_REPORT_S` seconds after (the holder may change)."""
    started = time.monotonic()
    reported = None
    while True:
        now = time.monotonic()
        if reported is None or now - reported >= WAIT_REPORT_S:
            waited = '' if reported is None else \
                f' (waited {now - started:.0f} s so far)'
            print(f'{folder}: waiting for {_describe_writer(fd)} to finish '
                  f'writing this output{waited}', file=sys.stderr,
                  flush=True)
            reported = now
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            time.sleep(WAIT_POLL_S)


def _check_lock_file(lock: str, fd: int, info: os.stat_result) -> None:
    """Refuse a lock file the package did not make before it is written:
    one with other names (a hard link to a file elsewhere), or content
    that is not a writer record (a file of the user's named ``.lock``).
    Empty is a lock file whose writer has not recorded itself yet."""
    if info.st_nlink != 1:
        raise OutputFolderError(
            f'{lock}: the lock file has {info.st_nlink} names (a hard link '
            f'to another file); it is not written through, so that file is '
            f'left as it is: remove {lock}')
    content = os.pread(fd, min(info.st_size, 1 << 16), 0)
    if content:
        try:
            record = parse_json(content.decode(), lock, 'writer record')
            if not isinstance(record, dict) or 'pid' not in record:
                raise ValueError('no pid')
        except (ValueError, UnicodeDecodeError):
            raise OutputFolderError(
                f'{lock}: a file this package did not make is where the '
                f'output folder\'s lock file belongs; it is not '
                f'overwritten: move it away') from None


def check_named_folder(folder: str) -> None:
    """Refuse a link or a file at ``folder``, a folder the package names
    itself: it is neither followed nor removed."""
    try:
        if stat.S_ISDIR(os.lstat(folder).st_mode):
            return
    except FileNotFoundError:
        return
    raise OutputFolderError(f'{folder}: a link or file where this package '
                            f'makes its own folder; it is not followed or '
                            f'removed: move it away')


def _take_lock(folder: str, lock: str, wait: bool, named: bool) -> int:
    """The open, exclusively locked lock file ``lock`` of ``folder``,
    recording this process; made again where another process removed it
    meanwhile."""
    while True:
        if named:
            check_named_folder(folder)
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as err:
            raise OutputFolderError(
                f'{folder}: cannot be made the output folder '
                f'({err.strerror}: a file is there, or on the way)') from err
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | _NOFOLLOW, 0o666)
        except FileNotFoundError:
            continue  # the folder was removed meanwhile: its writer is done
        except OSError as err:
            if osp.islink(lock):  # O_NOFOLLOW: not our lock file
                discard(lock)
                continue
            raise OutputFolderError(f'{folder}: cannot make its lock file '
                                    f'{lock}: {err.strerror}') from err
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # a FIFO put there
            os.close(fd)
            discard(lock)
            continue
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                if not wait:
                    raise OutputFolderError(
                        f'{folder}: another process is writing this output '
                        f'({_describe_writer(fd)}); wait for it to end (or '
                        f'pass --wait), or stop it') from None
                _wait_for(folder, fd)
            try:  # the lock counts only on the file the path still names
                current = os.lstat(lock)
            except FileNotFoundError:
                current = None
            mine = os.fstat(fd)
            if current is None or (current.st_dev, current.st_ino) != (
                    mine.st_dev, mine.st_ino):
                os.close(fd)
                continue
            _check_lock_file(lock, fd, mine)
            os.ftruncate(fd, 0)
            os.pwrite(fd, _writer_record(), 0)
            return fd
        except BaseException:
            with contextlib.suppress(OSError):
                os.close(fd)
            raise


def _release(fd: int, lock: str) -> None:
    """Remove the lock file if it is still ``fd``'s, then unlock."""
    try:
        current, mine = os.lstat(lock), os.fstat(fd)
        if (current.st_dev, current.st_ino) == (mine.st_dev, mine.st_ino):
            os.unlink(lock)
    except FileNotFoundError:
        pass  # the folder was removed with its lock (a walk's state)
    finally:
        os.close(fd)


@contextlib.contextmanager
def own_folder(folder: str, job: Optional[str] = None, wait: bool = False,
               named: bool = False,
               claim: bool = True) -> Iterator[OwnedFolder]:
    """Hold ``folder`` (made if missing) for writing, for the block.

    Args:
        folder: the output folder (a link given by the user as the folder
            itself is followed; links inside it are not).
        job: which of several jobs that may write the folder at the same
            time this is (a shard, an output file's name); ``None`` for the
            folder's only job. Writers of the same job exclude each other.
        wait: wait for another writer of the job to finish instead of
            raising.
        named: the package names this folder itself (beside a user's
            output): a link or file at its path is refused, not followed.
        claim: the folder is the package's output, with a manifest of what
            it wrote (see the module): one with other files and no
            manifest, or holding an input, is refused before anything is
            made (:func:`check_output_folder`). ``False``: only the lock is
            taken (a folder the user keeps other files in); one that has a
            manifest is still recorded in.

    Raises:
        OutputFolderError: another process writes the job (naming its
            process id, host, command and start time), ``folder`` cannot
            be made a folder, or (``claim``) it is not the package's.
    """
    folder = os.fspath(folder)
    if named:
        check_named_folder(folder)
    if claim:
        check_output_folder(folder)
    lock = _lock_path(folder, job)
    fd = _take_lock(folder, lock, wait, named)
    try:
        manifest = osp.join(folder, MANIFEST_NAME)
        if claim:
            try:
                made = os.open(manifest, os.O_WRONLY | os.O_CREAT | os.O_EXCL
                               | _NOFOLLOW, 0o666)
            except FileExistsError:
                os.close(_open_manifest(manifest, os.O_RDONLY))
            else:
                with os.fdopen(made, 'wb') as f:
                    f.write(MANIFEST_HEADER)
        owned = OwnedFolder(folder, lock, claim or osp.lexists(manifest))
        if owned.claimed:
            _HELD.append(owned)
        try:
            yield owned
        finally:
            if owned.claimed:
                _HELD.remove(owned)
    finally:
        _release(fd, lock)


def open_append(path: str) -> BinaryIO:
    """Open the state file ``path`` for appending: made if missing; a link
    (never followed), a file with other names (hard links) or anything but
    a regular file is an :class:`OutputFolderError` naming it."""
    fd = _open_own_file(
        path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 'cannot append to it',
        'not a regular file of one name; a state file is not appended to '
        'through a link')
    return os.fdopen(fd, 'ab')


def add_wait_option(parser) -> None:
    """A tool's ``--wait``: wait for another writer of the same output
    instead of stopping (:func:`own_folder`)."""
    parser.add_argument(
        '--wait', action='store_true',
        help='if another process is writing the same output, wait for it '
        'to finish instead of stopping with its name')
