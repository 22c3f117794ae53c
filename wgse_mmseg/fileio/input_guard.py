"""No output over an input, and outputs that are files or streamed to.

Outputs are files, or streamed to
    An output path where a FIFO or a character device already lies
    (``/dev/null``, a shell's ``>(cat)``) is written through, never
    replaced by a regular file (:func:`~wgse_mmseg.fileio.atomic.atomic_path`);
    a socket, a block device or a folder where a file goes is refused
    naming it, by the tools before any work
    (:func:`~wgse_mmseg.fileio.output_folder.check_tool_outputs`,
    :func:`check_output_kind`).No input replaced
    While a tool runs (its ``main`` is wrapped by :func:`keeps_inputs`),
    every file the package reads as input (a spike file, an image, a
    config, a checkpoint, an ONNX model) is noted (:func:`note_input`) by
    its device and inode, so hard links and symbolic links are the same
    file; every output the package writes
    (:func:`~wgse_mmseg.fileio.atomic.atomic_path`) and every path it removes
    (:func:`~wgse_mmseg.fileio.output_folder.discard`) is checked
    against them (:func:`check_output`): an output over an input is an
    :class:`OutputFolderError` naming both, and nothing is written. Tools
    also check their output arguments against their other arguments
    before any work
    (:func:`~wgse_mmseg.fileio.output_folder.check_tool_outputs`). (A library
    caller may read a file and save it back; only a tool's run is guarded.) A
    lock or state file the package writes in place is one it made: a file with
    other names (a hard link) or content that is not its record is refused,
    never truncated.
"""
import functools
import os
import os.path as osp
import stat
import sys
from typing import Callable, Dict, Iterable, Iterator, Optional, Tuple

from ..errors import WgseError

__all__ = ['OutputFolderError']


class OutputFolderError(WgseError, ValueError):
    """An output folder this package cannot own as asked: another process
    writes it, or a path in it is a link or not what it must be; names the
    path."""


#: ``(st_dev, st_ino)`` -> the path it was read by, of every file read as
#: an input while a tool runs (:func:`note_input`, :func:`keeps_inputs`)
NOTED_INPUTS: Dict[Tuple[int, int], str] = {}


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
                NOTED_INPUTS.clear()
    return run


def file_identity(path) -> Optional[Tuple[int, int]]:
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
    identity = file_identity(path)
    if identity is not None:
        NOTED_INPUTS.setdefault(identity, os.fspath(path))


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
    identity = file_identity(path)
    if identity is None:
        return
    found = {file_identity(given): os.fspath(given) for given in inputs}
    source = found.get(identity) or NOTED_INPUTS.get(identity)
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
    :func:`~wgse_mmseg.fileio.atomic.atomic_path` does).

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


def real_parents(path: str) -> Iterator[Tuple[int, int]]:
    """``(st_dev, st_ino)`` of every folder above ``path``'s real location
    (links resolved), nearest first, up to the root."""
    current = osp.realpath(path)
    while True:
        parent = osp.dirname(current)
        if parent == current:
            return
        identity = file_identity(parent)
        if identity is not None:
            yield identity
        current = parent
