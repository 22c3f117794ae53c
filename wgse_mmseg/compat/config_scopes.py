"""Let mmengine find ``mmseg::`` base configs under the distribution that is
installed, and this package's own bases by their scope, ``wgse_mmseg::``.

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

``_base_ = ['wgse_mmseg::_base_/datasets/spike_cityscapes.py']`` in a config
anywhere on disk names the package's base config as if by its absolute
path (:func:`resolve_package_scope`). mmengine's own mechanism, an entry
``'wgse_mmseg'`` in ``MODULE2PACKAGE``, does not serve a plugin: it needs
``.mim/model-index.yml`` and ``.mim/configs`` in the package folder, which
the PEP 660 editable install of the onedl stack cannot have (onedl-mim would
find every config twice), and it gives every ``type=`` of those bases
``_scope_='wgse_mmseg'``, a scope without registries (the package registers
into MMSeg's), so nothing they name would build. The scope is read where the
package's set-up ran (its tools, ``mim train wgse_mmseg``, code that calls
``register_all_modules()``): mmengine reads a config's bases before its
``custom_imports``, so MMSeg's own ``tools/train.py`` would need a hook into
every Python process, which the package does not install.
"""
import importlib.metadata as metadata
import importlib.util
import os.path as osp
from typing import Dict, Optional, Tuple

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
        if importlib.util.find_spec(module) is None or \
                _installed(distribution):
            continue
        if providers is None:  # reads every installed distribution: once
            providers = metadata.packages_distributions()
        candidates = sorted(set(providers.get(module, ())))
        if len(candidates) == 1:
            MODULE2PACKAGE[module] = changed[module] = candidates[0]
    return changed


#: the scope of the package's base configs: ``wgse_mmseg::_base_/...``
PACKAGE_SCOPE = 'wgse_mmseg'


def package_configs() -> str:
    """The folder of the package's configs: ``.mim/configs`` of an install
    that carries them (a regular install; the egg-link install's links),
    else ``configs/`` of the checkout the package is imported from (the
    PEP 660 editable install, a checkout on ``PYTHONPATH``)."""
    package = osp.dirname(osp.dirname(osp.abspath(__file__)))
    for folder in (osp.join(package, '.mim', 'configs'),
                   osp.join(osp.dirname(package), 'configs')):
        if osp.isdir(folder):
            return folder
    raise FileNotFoundError(
        f'{PACKAGE_SCOPE}:: configs: neither {package}/.mim/configs nor '
        f'{osp.dirname(package)}/configs exists; reinstall wgse_mmseg')


def resolve_package_scope() -> bool:
    """Make mmengine's ``Config`` read a base ``wgse_mmseg::PATH`` as
    ``package_configs()/PATH``, with no scope recorded (as the absolute path
    would be); every other base as before. Returns whether this call
    changed ``Config``; idempotent."""
    from mmengine.config import Config
    original = Config._get_cfg_path
    if getattr(original, 'resolves', None) == PACKAGE_SCOPE:
        return False

    def _get_cfg_path(cfg_path: str,
                      filename: str) -> Tuple[str, Optional[str]]:
        scope, separator, relative = cfg_path.partition('::')
        if not separator or scope != PACKAGE_SCOPE:
            return original(cfg_path, filename)
        path = osp.join(package_configs(), relative)
        if not osp.isfile(path):
            raise FileNotFoundError(
                f'{filename}: base {cfg_path}: no such config in the '
                f'package ({path})')
        return path, None

    _get_cfg_path.resolves = PACKAGE_SCOPE
    Config._get_cfg_path = staticmethod(_get_cfg_path)
    return True
