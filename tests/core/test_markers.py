"""The complete-or-absent marker protocol."""
import json

from wgse_mmseg.core.markers import (file_digest, invalidate, is_complete,
                                     write_marker)


def test_a_marker_covers_the_recipe_and_every_file(tmp_path):
    a, b = tmp_path / 'a.bin', tmp_path / 'b.bin'
    a.write_bytes(b'spikes')
    b.write_bytes(b'label')
    marker = str(tmp_path / 'm.json')
    files = dict(a=str(a), b=str(b))
    recipe = dict(num_steps=9, threshold=1 / 0.6)
    assert not is_complete(marker, recipe, files)  # no marker yet
    write_marker(marker, recipe, files, dict(note='x'))
    assert is_complete(marker, recipe, files)
    with open(marker) as f:
        content = json.load(f)
    assert content['note'] == 'x'
    assert content['files']['a'] == file_digest(str(a))
    assert not is_complete(marker, dict(recipe, num_steps=10), files)
    assert not is_complete(marker, recipe, dict(a=str(a)))  # other files
    b.write_bytes(b'label!')  # a file changed after the marker
    assert not is_complete(marker, recipe, files)
    b.write_bytes(b'label')
    assert is_complete(marker, recipe, files)
    b.unlink()
    assert not is_complete(marker, recipe, files)
    invalidate(marker)
    invalidate(marker)  # twice is fine
    assert not (tmp_path / 'm.json').exists()


def test_malformed_markers_are_not_complete(tmp_path):
    a = tmp_path / 'a.bin'
    a.write_bytes(b'x')
    marker = tmp_path / 'm.json'
    for text in ('', '{', '[]', '{"recipe": 1}',
                 '{"recipe": 1, "files": []}', '{"recipe": 1, "files": {}}'):
        marker.write_text(text)
        assert not is_complete(str(marker), 1, dict(a=str(a)))
    marker.write_bytes(b'\xff\xfe')
    assert not is_complete(str(marker), 1, dict(a=str(a)))
