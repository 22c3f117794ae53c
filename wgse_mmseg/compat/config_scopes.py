"""Let mmengine find ``mmseg::`` base configs under the distribution that is
installed.

A config's ``_base_ = ['mmseg::_base_/models/pspnet_r50-d8.py']`` is looked
up by mmengine through the *distribution* named for the scope in
``mmengine.config.utils.MODULE2PACKAGE`` (``'mmseg': 'mmsegmentation'``).
The maintained fork publishes the same import package ``mmseg`` as
``onedl-mmsegmentation``, and onedl-mmengine 0.10.12 still maps the scope to
``mmsegmentation``, so every ``mmseg::`` base fails with ``mmsegmentation is
not installed``. :func:`map_scopes_to_installed_distributions` points each
scope whose named distribution is missing, but whose import package is
installed, at the distribution that provides it; scopes that resolve are
left alone (OpenMMLab's releases need nothing).
"""
import importlib.metadata as metadata
import importlib.util
from typing import Dict

__all__ = []


def _installed(distribution: str) -> bool:
    try:
        metadata.version(distribution)
        return True
    except metadata.PackageNotFoundError:
        return False


def map_scopes_to_installed_distributions() -> Dict[str, str]:
    """Repoint scopes of ``MODULE2PACKAGE`` (a dict mmengine shares among its
    modules) whose distribution is missing to the one distribution that
    provides their import package. Returns ``{scope: distribution}`` of the
    scopes changed; idempotent."""
    from mmengine.config.utils import MODULE2PACKAGE
    providers = None
    changed = {}
    for module, distribution in list(MODULE2PACKAGE.items()):
        if importlib.util.find_spec(module) is None or _installed(distribution):
            continue
        if providers is None:  # reads every installed distribution: once
            providers = metadata.packages_distributions()
        candidates = sorted(set(providers.get(module, ())))
        if len(candidates) == 1:
            MODULE2PACKAGE[module] = changed[module] = candidates[0]
    return changed
