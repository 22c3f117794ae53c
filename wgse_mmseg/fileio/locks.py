"""One writer at a time for every output a re-run may resume.

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
"""
import contextlib
import datetime
import fcntl
import hashlib
import json
import os
import os.path as osp
import socket
import stat
import sys
import time
from typing import Iterator, Optional

from ..errors import cut
from .bounded_reads import parse_json
from .input_guard import OutputFolderError
from .output_folder import (HELD_FOLDERS, LOCK_NAME, MANIFEST_HEADER,
                            MANIFEST_NAME, NOFOLLOW, OwnedFolder,
                            check_output_folder, discard, open_manifest)


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
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | NOFOLLOW, 0o666)
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
                               | NOFOLLOW, 0o666)
            except FileExistsError:
                os.close(open_manifest(manifest, os.O_RDONLY))
            else:
                with os.fdopen(made, 'wb') as f:
                    f.write(MANIFEST_HEADER)
        owned = OwnedFolder(folder, lock, claim or osp.lexists(manifest))
        if owned.claimed:
            HELD_FOLDERS.append(owned)
        try:
            yield owned
        finally:
            if owned.claimed:
                HELD_FOLDERS.remove(owned)
    finally:
        _release(fd, lock)


def add_wait_option(parser) -> None:
    """A tool's ``--wait``: wait for another writer of the same output
    instead of stopping (:func:`own_folder`)."""
    parser.add_argument(
        '--wait', action='store_true',
        help='if another process is writing the same output, wait for it '
        'to finish instead of stopping with its name')
