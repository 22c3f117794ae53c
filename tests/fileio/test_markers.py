"""The complete-or-absent marker protocol."""
import hashlib
import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wgse_mmseg.fileio.atomic import write_bytes
from wgse_mmseg.fileio.markers import (file_digest, invalidate, is_complete,
                                       read_marker, sample_problem,
                                       write_marker)


def test_a_marker_covers_the_recipe_and_every_file(tmp_path):
    a, b = str(tmp_path / 'a.bin'), str(tmp_path / 'b.bin')
    written = dict(a=write_bytes(a, b'spikes'), b=write_bytes(b, b'label'))
    assert written['a'].size == 6 and written['a'].sha256 == \
        hashlib.sha256(b'spikes').hexdigest()
    marker = str(tmp_path / 'm.json')
    files = dict(a=a, b=b)
    recipe = dict(num_steps=9, threshold=1 / 0.6)
    assert not is_complete(marker, recipe, files)  # no marker yet
    write_marker(marker, recipe, written, dict(note='x'))
    assert is_complete(marker, recipe, files)
    with open(marker) as f:
        content = json.load(f)
    assert content['note'] == 'x'
    assert content['files']['a'] == dict(size=6, sha256=file_digest(a))
    assert not is_complete(marker, dict(recipe, num_steps=10), files)
    assert not is_complete(marker, recipe, dict(a=a))  # other files
    with open(b, 'wb') as f:
        f.write(b'label!')  # a file changed after the marker
    assert not is_complete(marker, recipe, files)
    with open(b, 'wb') as f:
        f.write(b'label')
    assert is_complete(marker, recipe, files)
    (tmp_path / 'b.bin').unlink()
    assert not is_complete(marker, recipe, files)
    invalidate(marker)
    invalidate(marker)  # twice is fine
    assert not (tmp_path / 'm.json').exists()


def test_a_marker_records_what_its_run_wrote_not_what_is_on_disk(tmp_path):
    """Another run replaces a file between this run's write and its marker:
    the marker describes this run's bytes, so the sample is not taken for
    complete."""
    path, marker = str(tmp_path / 'label.png'), str(tmp_path / 'm.json')
    mine = write_bytes(path, b'this run')
    write_bytes(path, b'that run')  # same size, other bytes
    write_marker(marker, 1, dict(label=mine))
    assert not is_complete(marker, 1, dict(label=path))
    assert sample_problem(marker, dict(label=path)) is None  # sizes agree
    assert sample_problem(marker, dict(label=path), full=True) == \
        'digest differs'


def test_sample_problems_name_the_reason(tmp_path):
    spike, label = str(tmp_path / 's.spk'), str(tmp_path / 'l.png')
    marker = str(tmp_path / 's.json')
    files = dict(spike=spike, label=label)
    assert sample_problem(marker, files) == 'no marker'
    written = dict(spike=write_bytes(spike, b'0101'),
                   label=write_bytes(label, b'19'))
    write_marker(marker, {}, written)
    assert sample_problem(marker, files) is None
    assert sample_problem(marker, files, full=True) is None
    assert sample_problem(marker, dict(spike=spike)) == 'other files'
    write_bytes(label, b'190')
    assert sample_problem(marker, files) == 'size differs'
    (tmp_path / 'l.png').unlink()
    assert sample_problem(marker, files) == 'missing file'
    with open(marker, 'w') as f:
        f.write('{"recipe": {}, "files": {"spike": "abc"}}')  # old format
    assert sample_problem(marker, files) == 'malformed marker'


def test_malformed_markers_are_not_complete(tmp_path):
    a = tmp_path / 'a.bin'
    a.write_bytes(b'x')
    marker = tmp_path / 'm.json'
    record = dict(size=1, sha256=file_digest(str(a)))
    for text in ('', '{', '[]', '{"recipe": 1}',
                 '{"recipe": 1, "files": []}', '{"recipe": 1, "files": {}}',
                 '{"recipe": 1, "files": {"a": "%s"}}' % record['sha256'],
                 '[' * 100000 + ']' * 100000,
                 json.dumps(dict(recipe=1, files=dict(a=record),
                                 pad='x' * (1 << 20)))):
        marker.write_text(text)
        assert not is_complete(str(marker), 1, dict(a=str(a)))
        assert sample_problem(str(marker), dict(a=str(a))) == \
            'malformed marker'
    marker.write_bytes(b'\xff\xfe')
    assert not is_complete(str(marker), 1, dict(a=str(a)))
    marker.write_text(json.dumps(dict(recipe=1, files=dict(a=record))))
    assert is_complete(str(marker), 1, dict(a=str(a)))


_JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False)
    | st.text(max_size=10),
    lambda children: st.lists(children, max_size=3)
    | st.dictionaries(st.text(max_size=5), children, max_size=3),
    max_leaves=10)


@given(content=_JSON)
def test_any_marker_content_is_read_or_refused(tmp_path_factory, content):
    """Whatever JSON a marker holds: a well-formed marker or ``None``,
    never an exception."""
    marker = str(tmp_path_factory.mktemp('m') / 'm.json')
    with open(marker, 'w') as f:
        json.dump(content, f)
    read = read_marker(marker)
    assert read is None or read == content
    problem = sample_problem(marker, dict(a=marker))
    assert problem in (None, 'malformed marker', 'other files',
                       'size differs')


@pytest.mark.parametrize('full', [False, True])
def test_a_marker_over_the_limit_is_malformed(tmp_path, full):
    from wgse_mmseg.limits import TEXT_FILE_LIMIT_BYTES
    marker = tmp_path / 'm.json'
    marker.write_bytes(b' ' * (TEXT_FILE_LIMIT_BYTES + 1))
    assert sample_problem(str(marker), dict(a=str(marker)), full) == \
        'malformed marker'
