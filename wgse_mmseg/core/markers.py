"""Complete or absent: a marker file that says a sample's files are whole.

A writer that makes several files per sample (the Spike-Cityscapes converter,
the synthetic dataset) and resumes after an interruption must not take a
half-written or stale sample for done. The protocol:

1. :func:`is_complete` before the work: the marker exists, holds the same
   recipe (every setting the files depend on, as JSON values) and the
   SHA-256 of each file it covers matches;
2. otherwise :func:`invalidate` (remove the marker), write the files (each
   atomically), then :func:`write_marker` last, atomically.

A process killed at any point leaves the sample without a valid marker, so
the next run, with these settings or others, redoes it.
"""
import hashlib
import json
import os
from typing import Any, Dict, Mapping, Optional

from .io import atomic_output

__all__ = ['file_digest', 'is_complete', 'invalidate', 'write_marker']


def file_digest(path: str) -> str:
    """SHA-256 of the file at ``path``, hex."""
    digest = hashlib.sha256()
    with open(path, 'rb') as f:
        for block in iter(lambda: f.read(1 << 20), b''):
            digest.update(block)
    return digest.hexdigest()


def is_complete(marker: str, recipe: Any, files: Mapping[str, str]) -> bool:
    """Whether ``marker`` holds ``recipe`` and the digests of ``files``
    (name -> path) as they are now. A missing, unreadable or malformed
    marker, or a missing file, is not complete."""
    try:
        with open(marker) as f:
            content = json.load(f)
        if not isinstance(content, dict) or content.get('recipe') != recipe:
            return False
        digests = content.get('files')
        return isinstance(digests, dict) and set(digests) == set(files) and \
            all(digests[name] == file_digest(path)
                for name, path in files.items())
    except (OSError, ValueError):  # json.JSONDecodeError is a ValueError
        return False


def invalidate(marker: str) -> None:
    """Remove ``marker`` if it exists: the sample is not done until it is
    rewritten."""
    try:
        os.remove(marker)
    except FileNotFoundError:
        pass


def write_marker(marker: str, recipe: Any, files: Mapping[str, str],
                 extra: Optional[Dict[str, Any]] = None,
                 default=None) -> None:
    """Write ``marker`` atomically: ``recipe``, the digests of ``files``
    and ``extra`` fields (``default`` serialises what JSON cannot)."""
    content = dict(recipe=recipe, files={name: file_digest(path)
                                         for name, path in files.items()})
    content.update(extra or {})
    text = json.dumps(content, indent=1, default=default)
    with atomic_output(marker) as f:
        f.write(text.encode())
