"""Atomic writes: an output appears whole or not at all.
"""
import contextlib
import errno
import hashlib
import os
import os.path as osp
import re
import secrets
import shutil
import tempfile
from typing import BinaryIO, Dict, Iterator, List, NamedTuple, Sequence

from .input_guard import check_output, check_output_kind
from .output_folder import note_written


@contextlib.contextmanager
def atomic_path(path: str) -> Iterator[str]:
    """A temporary path to write ``path``'s content to, so that ``path``
    appears whole or not at all (for writers that take a file name, such
    as OpenCV's ``VideoWriter``).

    The temporary file lies beside ``path``, is named after it,
    ``.tmp-<name>.<random><ext>`` (:func:`temporaries_of`), and is renamed
    over ``path`` when the block ends without error; on any error it is
    removed and ``path`` is untouched. It is created with the permissions
    ``open`` would give (mode ``0o666`` less the umask, applied by the
    kernel: no process-wide setting is read or changed), exclusively, never
    through a link. A process killed mid-write leaves one that the next run
    for that target can find and remove, without touching the temporaries
    of other processes writing beside it. A ``path`` that is an input of
    this process (:func:`~wgse_mmseg.fileio.input_guard.check_output`) is
    refused before anything is written, and again before the rename. A
    file written inside a folder the package holds is recorded in its
    manifest (:func:`~wgse_mmseg.fileio.output_folder.note_written`).

    Where a FIFO or a character device lies at ``path`` (``/dev/null``, a
    shell's ``>(cat)``), the temporary file is made in the system's
    temporary folder and, once whole, its bytes are written through to
    ``path``, which is never replaced; a FIFO no process reads is an
    ``OSError`` naming it, not a wait. A socket, a block device or a
    folder at ``path`` is refused before anything is written
    (:func:`~wgse_mmseg.fileio.input_guard.check_output_kind`).

    An ``OSError`` that names no file (``No space left on device``,
    ``File too large``, ``Read-only file system`` while writing) is raised
    again naming ``path``, of the same ``OSError`` subclass.
    """
    check_output(path)
    streamed = check_output_kind(path) is not None
    directory = (tempfile.gettempdir() if streamed else
                 osp.dirname(osp.abspath(path)))
    try:
        os.makedirs(directory, exist_ok=True)
        tmp = _create_temporary(directory, osp.basename(path),
                                osp.splitext(path)[1])
    except OSError as err:
        raise _naming(path, err) from err
    try:
        yield tmp
        check_output(path)
        if streamed:
            _write_through(tmp, path)
        else:
            os.replace(tmp, path)
            note_written(path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        if isinstance(err, OSError) and err.filename is None:
            raise _naming(path, err) from err
        raise
    finally:
        if streamed:
            with contextlib.suppress(OSError):
                os.remove(tmp)


def _naming(path: str, err: OSError) -> OSError:
    """``err``, an error of writing ``path``, as one that names it: the
    same errno, so the same ``OSError`` subclass."""
    if err.filename is not None or path in str(err.strerror):
        return err
    return OSError(err.errno, f'{path}: cannot be written: '
                   f'{err.strerror or err}')


def _write_through(tmp: str, path: str) -> None:
    """Write the bytes of the file ``tmp`` into ``path``, a FIFO or a
    character device, opened without creating or truncating anything."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY)
    except OSError as err:
        if err.errno == errno.ENXIO:
            raise OSError(err.errno, f'{path}: a FIFO that no process '
                          f'reads; start its reader first') from err
        raise
    try:
        os.set_blocking(fd, True)
        with open(tmp, 'rb') as source, os.fdopen(fd, 'wb',
                                                  closefd=False) as out:
            shutil.copyfileobj(source, out)
    finally:
        os.close(fd)


def _create_temporary(directory: str, name: str, suffix: str) -> str:
    """Create, empty, the temporary file ``.tmp-<name>.<random><suffix>``
    in ``directory`` and return its path: ``O_EXCL`` (a new file, never an
    existing one or a link's target), mode ``0o666`` less the umask."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, 'O_NOFOLLOW',
                                                           0)
    while True:
        tmp = osp.join(directory,
                       f'.tmp-{name}.{secrets.token_hex(6)}{suffix}')
        try:
            os.close(os.open(tmp, flags, 0o666))
            return tmp
        except FileExistsError:
            continue


@contextlib.contextmanager
def atomic_output(path: str) -> Iterator[BinaryIO]:
    """Open ``path`` for binary writing so that it appears whole or not at
    all: the file of :func:`atomic_path`."""
    with atomic_path(path) as tmp, open(tmp, 'wb') as f:
        yield f


def temporaries_of(paths: Sequence[str]) -> List[str]:
    """The temporary files :func:`atomic_output` left beside ``paths``
    (a process killed mid-write), listing each folder once."""
    patterns: Dict[str, list] = {}
    for path in paths:
        directory, name = osp.split(osp.abspath(path))
        patterns.setdefault(directory, []).append(re.compile(
            re.escape(f'.tmp-{name}.') + r'[A-Za-z0-9_]+' +
            re.escape(osp.splitext(name)[1])))
    found = []
    for directory, names in patterns.items():
        if not osp.isdir(directory):
            continue
        for entry in os.listdir(directory):
            if entry.startswith('.tmp-') and any(
                    pattern.fullmatch(entry) for pattern in names):
                found.append(osp.join(directory, entry))
    return sorted(found)


class WrittenFile(NamedTuple):
    """What a writer put in a file: its size in bytes and the SHA-256 (hex)
    of those bytes, computed from memory, not read back from disk."""
    size: int
    sha256: str


def write_bytes(path: str, data: bytes) -> WrittenFile:
    """Write ``data`` to ``path``, appearing complete or not at all
    (:func:`atomic_output`); returns its size and SHA-256."""
    with atomic_output(path) as f:
        f.write(data)
    return WrittenFile(len(data), hashlib.sha256(data).hexdigest())
