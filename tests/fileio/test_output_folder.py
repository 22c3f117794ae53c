"""Owning an output folder (wgse_mmseg.fileio.output_folder) with real
processes: a second writer refused naming the first, or waiting for it; a
killed writer's lock freed by the kernel; links at the lock, at files and
on the way never followed; state files never appended to through a link."""
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading

import pytest

from wgse_mmseg.fileio import input_guard, locks, output_folder
from wgse_mmseg.fileio.atomic import write_bytes
from wgse_mmseg.fileio.input_guard import OutputFolderError
from wgse_mmseg.fileio.locks import own_folder
from wgse_mmseg.fileio.output_folder import MANIFEST_NAME, discard, open_append

#: a process that owns FOLDER (job JOB, or None), says 'held', and keeps it
#: until its stdin closes; with WAIT, says 'trying' first and waits
HOLDER = textwrap.dedent('''
    import os.path as osp, sys, types
    fileio = osp.dirname(sys.argv[6])
    # the package's folders without their __init__: nothing else to import
    for name, path in (('wgse_mmseg', osp.dirname(fileio)),
                       ('wgse_mmseg.fileio', fileio)):
        sys.modules[name] = types.ModuleType(name)
        sys.modules[name].__path__ = [path]
    from wgse_mmseg.fileio.locks import own_folder
    folder, job, wait, log = sys.argv[1:5]
    print('trying', flush=True)
    with own_folder(folder, None if job == '-' else job, wait == 'wait'):
        with open(log, 'a') as f:
            f.write('start %s\\n' % sys.argv[5])
        print('held', flush=True)
        sys.stdin.read()
        with open(log, 'a') as f:
            f.write('end %s\\n' % sys.argv[5])
''')


def _holder(folder, log, name, job='-', wait='nowait'):
    return subprocess.Popen(
        [sys.executable, '-c', HOLDER, str(folder), job, wait, str(log),
         name, output_folder.__file__], stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(process, word):
    for line in process.stdout:
        if line.strip() == word:
            return
    raise AssertionError(process.stderr.read())


def test_a_second_writer_is_refused_naming_the_first(tmp_path):
    folder, log = tmp_path / 'out', tmp_path / 'log'
    first = _holder(folder, log, 'first')
    _wait_for(first, 'held')
    with pytest.raises(OutputFolderError) as info:
        with own_folder(str(folder)):
            pass
    message = str(info.value)
    assert str(folder) in message
    assert f'process {first.pid} on host {socket.gethostname()}' in message
    assert 'started 20' in message
    assert '-c' in message  # the first writer's command line
    second = _holder(folder, log, 'second')  # another process: refused too
    assert second.wait(60) == 1
    assert f'process {first.pid}' in second.stderr.read()
    first.communicate('', timeout=60)
    assert log.read_text() == 'start first\nend first\n'
    # the lock file goes with its writer
    assert os.listdir(folder) == [MANIFEST_NAME]
    with own_folder(str(folder)):  # free again
        pass


def test_with_wait_the_second_writer_follows_the_first(tmp_path):
    folder, log = tmp_path / 'out', tmp_path / 'log'
    first = _holder(folder, log, 'first')
    _wait_for(first, 'held')
    second = _holder(folder, log, 'second', wait='wait')
    _wait_for(second, 'trying')
    second.stdin.close()  # it leaves as soon as it holds the folder
    first.communicate('', timeout=60)
    assert second.wait(60) == 0, second.stderr.read()
    assert log.read_text().splitlines() == [
        'start first', 'end first', 'start second', 'end second']
    assert os.listdir(folder) == [MANIFEST_NAME]


def test_jobs_of_one_folder_run_together_and_exclude_their_twins(tmp_path):
    folder, log = tmp_path / 'out', tmp_path / 'log'
    one = _holder(folder, log, 'one', job='shard-1-of-2')
    _wait_for(one, 'held')
    with own_folder(str(folder), job='shard-2-of-2'):  # another job: free
        with pytest.raises(OutputFolderError, match=f'process {one.pid}'):
            with own_folder(str(folder), job='shard-1-of-2'):
                pass
    one.communicate('', timeout=60)


def test_a_killed_writer_leaves_no_lock_held(tmp_path):
    folder, log = tmp_path / 'out', tmp_path / 'log'
    first = _holder(folder, log, 'first')
    _wait_for(first, 'held')
    os.kill(first.pid, signal.SIGKILL)
    first.wait(60)
    with own_folder(str(folder)):  # the kernel released it
        pass
    assert os.listdir(folder) == [MANIFEST_NAME]


def test_many_threads_and_processes_one_at_a_time(tmp_path):
    """Eight writers (four processes, four threads of this one) each
    append start/end to a log inside the lock: the log never interleaves."""
    folder, log = tmp_path / 'out', tmp_path / 'log'
    processes = [_holder(folder, log, f'p{i}', wait='wait') for i in range(4)]
    for process in processes:
        process.stdin.close()

    def thread_writer(name):
        with own_folder(str(folder), wait=True):
            with open(log, 'a') as f:
                f.write(f'start {name}\n')
            with open(log, 'a') as f:
                f.write(f'end {name}\n')
    threads = [threading.Thread(target=thread_writer, args=(f't{i}', ))
               for i in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(120)
    for process in processes:
        assert process.wait(120) == 0, process.stderr.read()
    lines = log.read_text().splitlines()
    assert len(lines) == 16
    for start, end in zip(lines[::2], lines[1::2]):
        assert start.split()[0] == 'start' and end == 'end ' + \
            start.split()[1]


def test_a_link_at_the_lock_is_not_followed(tmp_path):
    outside = tmp_path / 'precious.txt'
    outside.write_text('keep me')
    folder = tmp_path / 'out'
    folder.mkdir()
    os.symlink(outside, folder / '.lock')
    with own_folder(str(folder)):
        assert not os.path.islink(folder / '.lock')
        record = json.loads((folder / '.lock').read_text())
        assert record['pid'] == os.getpid()
    assert outside.read_text() == 'keep me'
    assert os.listdir(folder) == [MANIFEST_NAME]
    os.mkfifo(folder / '.lock')  # opened, it would not be a lock file
    with own_folder(str(folder)):
        assert os.path.isfile(folder / '.lock')
    assert os.listdir(folder) == [MANIFEST_NAME]


def test_a_folder_the_package_names_refuses_a_link_or_file(tmp_path):
    outside = tmp_path / 'elsewhere'
    outside.mkdir()
    (outside / 'data').write_text('keep me')
    state = tmp_path / 'walk.mp4.partial'
    os.symlink(outside, state)
    with pytest.raises(OutputFolderError, match='partial: a link or file'):
        with own_folder(str(state), named=True):
            pass
    assert os.path.islink(state)
    assert sorted(os.listdir(outside)) == ['data']
    os.unlink(state)
    state.write_text('a file')
    with pytest.raises(OutputFolderError, match='partial: a link or file'):
        with own_folder(str(state), named=True):
            pass
    assert state.read_text() == 'a file'
    # a folder the user names is followed, not replaced
    target = tmp_path / 'target'
    target.mkdir()
    os.symlink(target, tmp_path / 'given')
    with own_folder(str(tmp_path / 'given')) as owned:
        owned.file(os.path.join(owned.root, 'a', 'b.txt'))
    assert (target / 'a').is_dir()
    (tmp_path / 'plain').write_text('x')
    with pytest.raises(OutputFolderError, match='plain: not a folder'):
        with own_folder(str(tmp_path / 'plain')):
            pass


def test_paths_inside_never_lead_out(tmp_path):
    outside = tmp_path / 'outside'
    outside.mkdir()
    (outside / 'secret.txt').write_text('keep me')
    root = tmp_path / 'out'
    with own_folder(str(root)) as owned:
        # a link at a file's path is removed, its target kept
        os.symlink(outside / 'secret.txt', root / 'sample.png')
        path = owned.file(str(root / 'sample.png'))
        assert not os.path.lexists(path)
        # a FIFO (a read would block) is removed too
        os.mkfifo(root / 'fifo.json')
        assert not os.path.lexists(owned.file(str(root / 'fifo.json')))
        # a regular file stays for its writer to verify
        (root / 'kept.txt').write_text('mine')
        assert owned.file(str(root / 'kept.txt')) == str(root / 'kept.txt')
        assert (root / 'kept.txt').read_text() == 'mine'
        # a linked folder on the way is refused, naming it
        os.symlink(outside, root / 'city')
        with pytest.raises(OutputFolderError, match=r'city: a symbolic link'):
            owned.file(str(root / 'city' / 'a.png'))
        (root / 'dir.png').mkdir()
        with pytest.raises(OutputFolderError, match='dir.png: a folder'):
            owned.file(str(root / 'dir.png'))
        with pytest.raises(OutputFolderError, match='not inside'):
            owned.file(str(tmp_path / 'elsewhere.png'))
    assert sorted(os.listdir(outside)) == ['secret.txt']
    assert (outside / 'secret.txt').read_text() == 'keep me'


def test_state_is_never_appended_to_through_a_link(tmp_path):
    outside = tmp_path / 'precious.csv'
    outside.write_text('keep me\n')
    os.symlink(outside, tmp_path / 'progress.csv')
    with pytest.raises(OutputFolderError, match='progress.csv'):
        open_append(str(tmp_path / 'progress.csv'))
    os.link(outside, tmp_path / 'hard.csv')
    with pytest.raises(OutputFolderError, match='hard.csv'):
        open_append(str(tmp_path / 'hard.csv'))
    os.mkfifo(tmp_path / 'fifo.csv')  # no reader: refused, not waited on
    with pytest.raises(OutputFolderError, match='fifo.csv'):
        open_append(str(tmp_path / 'fifo.csv'))
    assert outside.read_text() == 'keep me\n'
    with open_append(str(tmp_path / 'new.csv')) as f:
        f.write(b'row\n')
    assert (tmp_path / 'new.csv').read_bytes() == b'row\n'


@pytest.mark.parametrize('record', [b'[' * 4000, b'\xff\xfe', b'{"pid": []}',
                                    b''])
def test_a_damaged_writer_record_still_refuses_clearly(tmp_path, record):
    """Whatever the lock file holds (nesting past the parser's recursion,
    bytes that are not UTF-8, fields of the wrong kind, nothing), a second
    writer is refused with the package's error, not the parser's."""
    with own_folder(str(tmp_path)):
        with open(tmp_path / '.lock', 'r+b') as lock:
            lock.truncate(0)
            lock.write(record)
        with pytest.raises(OutputFolderError,
                           match='a process that has not yet recorded'):
            with own_folder(str(tmp_path)):
                pass


@pytest.fixture
def guarded():
    """A tool's run (:func:`input_guard.keeps_inputs`) for the test."""
    input_guard._GUARDS[0] += 1
    yield
    input_guard._GUARDS[0] -= 1
    input_guard.NOTED_INPUTS.clear()


@pytest.mark.parametrize('name', ['same', 'hard link', 'symbolic link'])
def test_an_output_that_is_an_input_is_refused_naming_both(tmp_path, name,
                                                           guarded):
    from wgse_mmseg.fileio.atomic import write_bytes
    source = tmp_path / 'input.bin'
    source.write_bytes(b'user data')
    input_guard.note_input(str(source))
    out = tmp_path / 'out.bin'
    if name == 'same':
        out = source
    elif name == 'hard link':
        os.link(source, out)
    else:
        out.symlink_to(source)
    with pytest.raises(OutputFolderError) as info:
        write_bytes(str(out), b'output')
    assert str(out) in str(info.value) and str(source) in str(info.value)
    assert source.read_bytes() == b'user data'
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        {'input.bin', out.name})  # no temporary left
    with pytest.raises(OutputFolderError):
        discard(str(out) if name != 'symbolic link' else str(source))
    assert source.read_bytes() == b'user data'


def test_outputs_are_checked_against_the_given_inputs_and_nothing_else(
        tmp_path):
    source, other = tmp_path / 'a', tmp_path / 'b'
    source.write_bytes(b'a')
    other.write_bytes(b'b')
    os.link(source, tmp_path / 'a2')
    input_guard.check_output(str(other), [str(source)])
    input_guard.check_output(str(tmp_path / 'missing'), [str(source)])
    with pytest.raises(OutputFolderError, match='a2.*the input .*/a '):
        input_guard.check_output(str(tmp_path / 'a2'), [str(source)])
    # outside a tool's run nothing read is remembered: a library caller
    # may read a file and save it back
    input_guard.note_input(str(source))
    input_guard.check_output(str(source))


def test_a_tools_output_arguments_against_its_other_arguments(tmp_path):
    import argparse
    source = tmp_path / 'rec.npy'
    source.write_bytes(b'x')
    os.link(source, tmp_path / 'alias.png')
    args = argparse.Namespace(spikes=str(source), out=str(tmp_path / 'n.png'),
                              many=[str(tmp_path / 'x'), str(source)],
                              count=3, device='cpu')
    output_folder.check_tool_outputs(args, 'out')
    args.out = str(tmp_path / 'alias.png')
    with pytest.raises(OutputFolderError, match='alias.png.*rec.npy'):
        output_folder.check_tool_outputs(args, 'out')
    args.out = None  # an unset output
    output_folder.check_tool_outputs(args, 'out')
    with pytest.raises(OutputFolderError):  # an input folder as the output
        output_folder.check_tool_outputs(
            argparse.Namespace(root=str(tmp_path), out_dir=str(tmp_path)),
            'out_dir')


def test_keeps_inputs_scopes_the_notes_and_ends_a_refusal_in_one_line(
        tmp_path):
    from wgse_mmseg.fileio.atomic import write_bytes
    source = tmp_path / 'in'
    source.write_bytes(b'keep')

    @input_guard.keeps_inputs
    def main():
        input_guard.note_input(str(source))
        write_bytes(str(source), b'lost')

    with pytest.raises(SystemExit) as info:
        main()
    assert 'error:' in str(info.value.code) and str(source) in str(
        info.value.code)
    assert source.read_bytes() == b'keep'
    assert not input_guard.NOTED_INPUTS and not input_guard._GUARDS[0]
    write_bytes(str(source), b'mine')  # outside a run: the caller's choice
    assert source.read_bytes() == b'mine'


def test_a_lock_file_hard_linked_to_a_user_file_is_not_written(tmp_path):
    folder = tmp_path / 'out'
    folder.mkdir()
    user = tmp_path / 'thesis.txt'
    user.write_text('years of work')
    os.link(user, folder / '.lock')
    with pytest.raises(OutputFolderError, match='2 names'):
        with own_folder(str(folder)):
            pass
    assert user.read_text() == 'years of work'


@pytest.mark.parametrize('content', [b'my notes', b'{"a": 1}', b'\xff\xfe'])
def test_a_user_file_where_the_lock_belongs_is_not_overwritten(tmp_path,
                                                               content):
    folder = tmp_path / 'out'
    folder.mkdir()
    (folder / '.lock').write_bytes(content)
    with pytest.raises(OutputFolderError, match='did not make'):
        with own_folder(str(folder)):
            pass
    assert (folder / '.lock').read_bytes() == content


def test_a_lock_left_by_a_killed_writer_is_taken(tmp_path):
    folder = tmp_path / 'out'
    folder.mkdir()
    (folder / '.lock').write_bytes(locks._writer_record())
    with own_folder(str(folder)):
        pass
    assert not (folder / '.lock').exists()


def test_a_waiting_writer_says_whom_it_waits_for_and_again_later(
        tmp_path, monkeypatch, capsys):
    folder, log = tmp_path / 'out', tmp_path / 'log'
    first = _holder(folder, log, 'first')
    _wait_for(first, 'held')
    monkeypatch.setattr(locks, 'WAIT_REPORT_S', 0.3)
    timer = threading.Timer(1.0, first.stdin.close)
    timer.start()
    try:
        with own_folder(str(folder), wait=True):
            pass
    finally:
        timer.cancel()
        first.stdin.close()
        first.wait(60)
    lines = [line for line in capsys.readouterr().err.splitlines()
             if 'waiting for' in line]
    assert len(lines) >= 2, lines
    assert all(f'process {first.pid} on host' in line for line in lines)
    assert 'waited' not in lines[0] and 'waited' in lines[-1]


def test_unshare_keeps_other_names_content_before_an_in_place_write(
        tmp_path):
    user = tmp_path / 'user.txt'
    user.write_text('mine')
    os.link(user, tmp_path / 'hard')
    (tmp_path / 'soft').symlink_to(user)
    (tmp_path / 'own').write_text('old')
    for name in ('hard', 'soft', 'own', 'missing'):
        output_folder.unshare(str(tmp_path / name))
        with open(tmp_path / name, 'w') as f:  # as a library writes
            f.write('new')
    assert user.read_text() == 'mine'
    assert os.stat(user).st_nlink == 1
    for name in ('hard', 'soft', 'own', 'missing'):
        assert (tmp_path / name).read_text() == 'new'
        assert not (tmp_path / name).is_symlink()


def test_an_existing_folder_of_other_files_is_refused_before_any_work(
        tmp_path):
    """A folder with files and no manifest (one the package did not make)
    is refused naming some of them, before anything is made in it; an
    empty folder is taken, and one the package made is taken again."""
    out = tmp_path / 'out'
    out.mkdir()
    for index in range(5):
        (out / f'notes{index}.txt').write_text('mine')
    with pytest.raises(OutputFolderError,
                       match=r'out: an existing folder this package did not '
                       r'make \(it holds notes0.txt, notes1.txt, notes2.txt '
                       r'and 2 more'):
        with own_folder(str(out)):
            pass
    assert sorted(os.listdir(out)) == [f'notes{i}.txt' for i in range(5)]
    empty = tmp_path / 'empty'
    empty.mkdir()
    with own_folder(str(empty)) as owned:
        assert owned.claimed
        write_bytes(str(empty / 'a.bin'), b'a')
    (empty / 'notes.txt').write_text('added later')
    with own_folder(str(empty)) as owned:  # the package's: taken again
        assert owned.written() == {'a.bin'}
    # a lock alone, beside a file the user keeps, claims nothing
    with own_folder(str(out), 'job', claim=False) as owned:
        assert not owned.claimed
    assert sorted(os.listdir(out)) == [f'notes{i}.txt' for i in range(5)]


def test_removal_takes_only_what_the_manifest_lists(tmp_path, guarded,
                                                    capsys):
    """clear and remove take the files the package wrote (at any depth)
    and the folders that leaves empty; a file the user added, a folder of
    the user's, and a listed name the user made a hard link of an input
    stay, and the folder stays with them, named on stderr."""
    source = tmp_path / 'recording.npy'
    source.write_bytes(b'user data')
    input_guard.note_input(str(source))
    out = tmp_path / 'out'
    with own_folder(str(out)) as owned:
        for name in ('a.bin', 'deep/er/b.bin', 'mixed/c.bin', 'linked.bin'):
            owned.file(str(out / name))
            write_bytes(str(out / name), b'package')
        assert owned.written() == {'a.bin', 'deep/er/b.bin', 'mixed/c.bin',
                                   'linked.bin'}
        (out / 'notes.txt').write_text('mine')
        (out / 'mixed' / 'mine.txt').write_text('mine')
        (out / 'theirs').mkdir()
        os.remove(out / 'linked.bin')
        os.link(source, out / 'linked.bin')
        owned.clear()
        assert sorted(os.listdir(out)) == [
            '.lock', MANIFEST_NAME, 'linked.bin', 'mixed', 'notes.txt',
            'theirs']
        assert os.listdir(out / 'mixed') == ['mine.txt']
        assert owned.written() == set()
        write_bytes(str(out / 'again.bin'), b'package')
        owned.remove()
    assert sorted(os.listdir(out)) == ['linked.bin', 'mixed', 'notes.txt',
                                       'theirs']
    assert source.read_bytes() == b'user data'
    assert 'out: kept: it holds files this package did not write' in \
        capsys.readouterr().err
    # nothing left of the user's: the folder goes
    only = tmp_path / 'only'
    with own_folder(str(only)) as owned:
        write_bytes(str(only / 'x' / 'y.bin'), b'package')
        owned.remove()
    assert not only.exists()


def test_no_folder_is_removed_as_a_tree(tmp_path):
    folder = tmp_path / 'folder'
    (folder / 'inner').mkdir(parents=True)
    (folder / 'inner' / 'mine.txt').write_text('mine')
    with pytest.raises(OutputFolderError, match='folder: a folder'):
        discard(str(folder))
    assert (folder / 'inner' / 'mine.txt').read_text() == 'mine'


@pytest.mark.parametrize('where', ['top', 'depth 4', 'symbolic link to it',
                                   'folder given as a link',
                                   'through a linked parent'])
def test_an_input_inside_an_output_folder_is_refused(tmp_path, guarded,
                                                     where):
    """An input anywhere under the output folder (at any depth, named
    through a link to it or to a folder above it, the output folder
    itself given through a link) is refused naming both, before anything
    is made; the input is untouched."""
    out = tmp_path / 'out'
    inside = out / 'a' / 'b' / 'c' if where == 'depth 4' else out
    inside.mkdir(parents=True)
    (out / MANIFEST_NAME).write_bytes(output_folder.MANIFEST_HEADER)
    source = inside / 'rec.npy'
    source.write_bytes(b'user data')
    given, folder = source, out
    if where == 'symbolic link to it':
        given = tmp_path / 'rec-link.npy'
        given.symlink_to(source)
    elif where == 'folder given as a link':
        folder = tmp_path / 'out-link'
        folder.symlink_to(out)
    elif where == 'through a linked parent':
        (tmp_path / 'via').symlink_to(out)
        given = tmp_path / 'via' / 'rec.npy'
    input_guard.note_input(str(given))
    with pytest.raises(OutputFolderError,
                       match=f'{folder}: this output folder holds the input '
                       f'{given}'):
        with own_folder(str(folder)):
            pass
    with pytest.raises(OutputFolderError, match='holds the input'):
        output_folder.check_output_folder(str(folder), [str(given)])
    assert source.read_bytes() == b'user data'
    assert not (out / '.lock').exists()


def test_a_hard_link_of_an_input_is_never_replaced_or_removed(tmp_path,
                                                              guarded):
    """A hard link of an input inside an output folder, at a name the
    package writes: the write is refused naming the input, and the
    folder's clearing leaves it."""
    source = tmp_path / 'rec.npy'
    source.write_bytes(b'user data')
    input_guard.note_input(str(source))
    out = tmp_path / 'out'
    with own_folder(str(out)) as owned:
        write_bytes(str(out / 'frame.png'), b'package')
        os.remove(out / 'frame.png')
        os.link(source, out / 'frame.png')
        with pytest.raises(OutputFolderError, match='the input'):
            write_bytes(str(out / 'frame.png'), b'package')
        owned.clear()
    assert (out / 'frame.png').read_bytes() == b'user data'
    assert os.stat(source).st_nlink == 2


def test_a_tools_folder_outputs_are_checked_before_any_work(tmp_path):
    import argparse
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'notes.txt').write_text('mine')
    data = tmp_path / 'data'
    (data / 'deep').mkdir(parents=True)
    (data / 'deep' / 'image.png').write_bytes(b'png')
    args = argparse.Namespace(out_dir=str(out), root=str(data))
    with pytest.raises(OutputFolderError, match='did not make'):
        output_folder.check_tool_outputs(args, folders=['out_dir'])
    # the input file inside the output folder, at depth
    args = argparse.Namespace(out_dir=str(data),
                              image=str(data / 'deep' / 'image.png'))
    with pytest.raises(OutputFolderError, match='holds the input'):
        output_folder.check_tool_outputs(args, folders=['out_dir'])
    args = argparse.Namespace(out_dir=str(tmp_path / 'new'),
                              root=str(data))
    output_folder.check_tool_outputs(args, folders=['out_dir'])
