"""Complete or absent: a marker file that says a sample's files are whole.

A writer that makes several files per sample (the Spike-Cityscapes converter,
the synthetic dataset) and resumes after an interruption must not take a
half-written or stale sample for done, and a reader must not serve one. The
protocol:

1. :func:`is_complete` before the work: the marker exists, holds the same
   recipe (every setting the files depend on, as JSON values) and the size
   and SHA-256 of each file it covers match the files on disk;
2. otherwise :func:`invalidate` (remove the marker), write the files (each
   atomically, with a writer that returns the size and SHA-256 of the bytes
   it wrote, :class:`~wgse_mmseg.fileio.atomic.WrittenFile`), then
   :func:`write_marker` last, atomically, with those records. A marker
   therefore describes the bytes its own run wrote: if another run replaced
   a file meanwhile, the marker does not match it.

A process killed at any point leaves the sample without a valid marker, so
the next run, with these settings or others, redoes it, and a dataset
(:func:`sample_problem`) skips it.

Marker content (JSON): ``recipe``, ``files``: name -> ``{"size": bytes,
"sha256": hex}``, and a writer's extra fields.
"""
import hashlib
import json
import os
from typing import Any, Dict, Mapping, Optional

from .atomic import WrittenFile, write_bytes
from .bounded_reads import load_json_file

__all__ = []


def file_digest(path: str) -> str:
    """SHA-256 of the file at ``path``, hex."""
    digest = hashlib.sha256()
    with open(path, 'rb') as f:
        for block in iter(lambda: f.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()


def read_marker(marker: str) -> Optional[dict]:
    """The marker's content when it exists and is well formed (a recipe,
    and ``files`` mapping names to ``{"size", "sha256"}``), else ``None``.
    A marker over :data:`~wgse_mmseg.limits.TEXT_FILE_LIMIT_BYTES`
    is not well formed."""
    try:
        content = load_json_file(marker, 'marker')
    except (OSError, ValueError):
        return None
    if not isinstance(content, dict) or 'recipe' not in content:
        return None
    files = content.get('files')
    if not isinstance(files, dict) or not files or not all(
            isinstance(record, dict) and set(record) == {'size', 'sha256'}
            for record in files.values()):
        return None
    return content


def sample_problem(marker: str, files: Mapping[str, str],
                   full: bool = False) -> Optional[str]:
    """Why the sample whose files are ``files`` (name -> path) is not
    complete, or ``None`` when it is.

    The cheap check: the marker exists and is well formed, names exactly
    these files, and each exists with its recorded size. ``full`` also
    compares each file's SHA-256 (reads every byte). Reasons: ``'no
    marker'``, ``'malformed marker'``, ``'other files'``, ``'missing
    file'``, ``'size differs'``, ``'digest differs'``.
    """
    if not os.path.exists(marker):
        return 'no marker'
    content = read_marker(marker)
    if content is None:
        return 'malformed marker'
    records = content['files']
    if set(records) != set(files):
        return 'other files'
    for name, path in files.items():
        try:
            size = os.path.getsize(path)
        except OSError:
            return 'missing file'
        if size != records[name]['size']:
            return 'size differs'
    if full and any(file_digest(path) != records[name]['sha256']
                    for name, path in files.items()):
        return 'digest differs'
    return None


def is_complete(marker: str, recipe: Any, files: Mapping[str, str]) -> bool:
    """Whether ``marker`` holds ``recipe`` and the sizes and digests of
    ``files`` (name -> path) as they are now. A missing, unreadable or
    malformed marker, or a missing file, is not complete."""
    content = read_marker(marker)
    return content is not None and content['recipe'] == recipe and \
        sample_problem(marker, files, full=True) is None


def invalidate(marker: str) -> None:
    """Remove ``marker`` if it exists: the sample is not done until it is
    rewritten."""
    try:
        os.remove(marker)
    except FileNotFoundError:
        pass


def write_marker(marker: str, recipe: Any,
                 written: Mapping[str, WrittenFile],
                 extra: Optional[Dict[str, Any]] = None,
                 default=None) -> None:
    """Write ``marker`` atomically: ``recipe``, the records of the files
    this run ``written`` (name ->
    :class:`~wgse_mmseg.fileio.atomic.WrittenFile`,
    as the writers returned them) and ``extra`` fields (``default``
    serialises what JSON cannot)."""
    content = dict(recipe=recipe, files={
        name: dict(size=record.size, sha256=record.sha256)
        for name, record in written.items()})
    content.update(extra or {})
    write_bytes(marker, json.dumps(content, indent=1,
                                   default=default).encode())
