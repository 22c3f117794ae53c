"""Atomic writes (wgse_mmseg.fileio.atomic.atomic_path and its writers): an
output that is a FIFO or a character device written through and never
replaced, a socket, block device or folder refused naming it; a failed
write (a full disk, a file-size limit) leaves no temporary and names the
file, keeping its ``OSError`` subclass."""
import argparse
import errno
import os
import resource
import signal
import socket
import stat
import tempfile
import threading
import time

import pytest

from wgse_mmseg.fileio import atomic
from wgse_mmseg.fileio.atomic import atomic_output, atomic_path, write_bytes
from wgse_mmseg.fileio.input_guard import OutputFolderError, check_output_kind
from wgse_mmseg.fileio.output_folder import check_tool_outputs

DATA = bytes(range(256)) * 1000  # more than a pipe's buffer


def _temporaries():
    return [n for n in os.listdir(tempfile.gettempdir())
            if n.startswith('.tmp-')]


def test_a_fifo_is_written_through_never_replaced(tmp_path):
    fifo = tmp_path / 'out.json'
    os.mkfifo(fifo)
    before = _temporaries()
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # a reader is there
    received = bytearray()

    def read():
        while len(received) < len(DATA):
            try:
                chunk = os.read(reader, 1 << 16)
            except BlockingIOError:
                chunk = b''
            received.extend(chunk)
            if not chunk:
                time.sleep(0.001)

    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    try:
        with atomic_output(str(fifo)) as f:
            f.write(DATA)
        thread.join(timeout=60)
    finally:
        os.close(reader)
    assert bytes(received) == DATA
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert sorted(os.listdir(tmp_path)) == ['out.json']
    assert _temporaries() == before


def test_a_fifo_nobody_reads_is_an_error_naming_it_not_a_wait(tmp_path):
    fifo = tmp_path / 'out.csv'
    os.mkfifo(fifo)
    before = _temporaries()
    with pytest.raises(OSError, match=f'{fifo}: a FIFO that no process '
                       f'reads') as info:
        write_bytes(str(fifo), b'rows')
    assert info.value.errno == errno.ENXIO
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert _temporaries() == before


@pytest.mark.skipif(os.geteuid() != 0, reason='mknod needs root')
def test_a_character_device_is_written_through_never_replaced(tmp_path):
    """A null device made in the test folder (``/dev/null`` itself is
    never risked): the write succeeds, the device stays a device."""
    null = tmp_path / 'null'
    os.mknod(null, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    with atomic_path(str(null)) as tmp:
        with open(tmp, 'wb') as f:
            f.write(DATA)
    write_bytes(str(null), DATA)
    assert stat.S_ISCHR(os.lstat(null).st_mode)
    assert os.lstat(null).st_rdev == os.makedev(1, 3)
    assert os.listdir(tmp_path) == ['null']


def test_a_socket_or_folder_at_an_output_is_refused_before_writing(
        tmp_path):
    server = socket.socket(socket.AF_UNIX)
    path = tmp_path / 'out.sock'
    server.bind(str(path))
    try:
        with pytest.raises(OutputFolderError, match=f'{path}: a socket'):
            write_bytes(str(path), b'x')
        assert stat.S_ISSOCK(os.lstat(path).st_mode)
    finally:
        server.close()
    folder = tmp_path / 'out.json'
    folder.mkdir()
    (folder / 'mine.txt').write_text('mine')
    with pytest.raises(OutputFolderError, match=f'{folder}: a folder'):
        write_bytes(str(folder), b'x')
    assert os.listdir(folder) == ['mine.txt']
    assert sorted(os.listdir(tmp_path)) == ['out.json', 'out.sock']


def test_the_tools_pre_flight_check_of_output_kinds(tmp_path):
    fifo = tmp_path / 'fifo'
    os.mkfifo(fifo)
    assert check_output_kind(str(fifo)) == 'fifo'
    assert check_output_kind(str(tmp_path / 'missing')) is None
    with pytest.raises(OutputFolderError, match='fifo: a fifo where the '
                       'output file goes; this output is written to a '
                       'file, not streamed'):
        check_output_kind(str(fifo), streamed=False)
    link = tmp_path / 'link'  # like /dev/fd/63: a link to the pipe
    link.symlink_to(fifo)
    assert check_output_kind(str(link)) == 'fifo'
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(tmp_path / 'sock'))
    try:
        args = argparse.Namespace(out=str(tmp_path / 'sock'))
        with pytest.raises(OutputFolderError, match='sock: a socket'):
            check_tool_outputs(args, 'out')
    finally:
        server.close()
    check_tool_outputs(argparse.Namespace(out=str(link)), 'out')


@pytest.mark.parametrize('error', [errno.ENOSPC, errno.EFBIG, errno.EROFS,
                                   errno.EACCES])
def test_a_failed_write_leaves_no_temporary_and_names_the_file(
        tmp_path, monkeypatch, error):
    """A write that fails after some bytes: the target is untouched, no
    temporary is left, the error names the target and keeps its errno
    (so its ``OSError`` subclass: ``PermissionError`` for EACCES)."""
    target = tmp_path / 'result.json'
    target.write_bytes(b'earlier')

    def failing(path, data):
        with atomic.atomic_output(path) as f:
            f.write(data[:10])
            f.flush()
            raise OSError(error, os.strerror(error))

    with pytest.raises(OSError) as info:
        failing(str(target), DATA)
    assert info.value.errno == error
    assert type(info.value) is type(OSError(error, 'x'))
    assert str(target) in str(info.value)
    assert target.read_bytes() == b'earlier'
    assert os.listdir(tmp_path) == ['result.json']


def test_a_file_size_limit_leaves_no_temporary_and_names_the_file(
        tmp_path):
    """RLIMIT_FSIZE below the write's size (SIGXFSZ ignored, so the
    kernel answers EFBIG): ``File too large`` naming the file, nothing
    left; the limit is restored afterwards."""
    target = tmp_path / 'big.bin'
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 16, hard))
    try:
        with pytest.raises(OSError) as info:
            write_bytes(str(target), DATA)
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, handler)
    assert info.value.errno == errno.EFBIG
    assert f'{target}: cannot be written: File too large' in str(info.value)
    assert os.listdir(tmp_path) == []


@pytest.mark.skipif(not os.path.isdir('/proc/self/fd'),
                    reason='no /proc file descriptors')
def test_a_descriptor_link_to_a_regular_file_is_refused(tmp_path):
    """``/dev/stdout`` redirected to a file is a link through
    ``/proc/<pid>/fd``: a rename would replace the link, so the write is
    refused naming it, before anything is made; the file keeps its
    content."""
    target = tmp_path / 'redirected.txt'
    target.write_bytes(b'earlier')
    with open(target, 'ab') as f:
        for path in (f'/proc/self/fd/{f.fileno()}',
                     f'/dev/fd/{f.fileno()}'):
            if not os.path.exists(path):
                continue
            with pytest.raises(OutputFolderError,
                               match=f'{path}: names an open file'):
                write_bytes(path, b'new')
    assert target.read_bytes() == b'earlier'
    assert os.listdir(tmp_path) == ['redirected.txt']
