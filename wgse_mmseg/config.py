"""Loading configs with the spike settings overridable from the command line.

The dataset base config sets ``num_steps`` (T), ``data_root`` and
``crop_size`` once, through mmengine's ``{{$ENV:default}}`` substitution, and
every field that depends on them (the loader's window, the preprocessor's
check and padding, the backbone's ``in_channels``) is derived from them when
the file is parsed. ``--cfg-options num_steps=41`` can therefore not be a
plain merge after parsing: :func:`load_config` turns these keys into the
environment variables the config reads, then merges the rest as usual.
"""
import os
from typing import Dict, Optional

from mmengine.config import Config

__all__ = ['SPIKE_SETTINGS', 'load_config']

#: ``--cfg-options`` key -> environment variable read by the config files.
SPIKE_SETTINGS = {
    'num_steps': 'WGSE_NUM_STEPS',
    'data_root': 'WGSE_DATA_ROOT',
    'crop_size': 'WGSE_CROP_SIZE',
}


def _as_env_value(key: str, value) -> str:
    if key == 'crop_size':
        if isinstance(value, str):
            value = value.split(',')
        sizes = [value] * 2 if isinstance(value, int) else list(value)
        if len(sizes) != 2:
            raise ValueError(f'crop_size must be H,W; got {value!r}')
        return ','.join(str(int(v)) for v in sizes)
    if key == 'num_steps' and int(value) < 1:
        raise ValueError(f'num_steps must be >= 1, got {value!r}')
    return str(value)


def load_config(path: str, cfg_options: Optional[Dict] = None) -> Config:
    """``Config.fromfile(path)`` with ``cfg_options`` applied.

    ``num_steps``, ``data_root`` and ``crop_size`` in ``cfg_options`` are
    applied before parsing (see module docstring); other keys are merged
    with ``Config.merge_from_dict``.
    """
    options = dict(cfg_options or {})
    saved = {}
    for key, env in SPIKE_SETTINGS.items():
        if key in options:
            saved[env] = os.environ.get(env)
            os.environ[env] = _as_env_value(key, options.pop(key))
    try:
        cfg = Config.fromfile(path)
    finally:
        for env, value in saved.items():
            if value is None:
                os.environ.pop(env, None)
            else:
                os.environ[env] = value
    if options:
        cfg.merge_from_dict(options)
    return cfg
