"""Reading checkpoint files that come from anywhere: weights only, and a
clear error naming the file for anything that is not a checkpoint."""
import os.path as osp

import torch

__all__ = []


class CheckpointError(ValueError):
    """A file that cannot be read as a checkpoint; names the file."""


def read_checkpoint(path: str) -> dict:
    """``torch.load(path, weights_only=True)`` on the CPU, as a dict.

    Raises:
        FileNotFoundError: no file at ``path``.
        CheckpointError: the file is not a weights-only torch checkpoint
            holding a dict (a text file, a truncated or corrupt archive, a
            pickle that needs code to load); the message names the file and
            what torch said.
    """
    if not osp.isfile(path):
        raise FileNotFoundError(f'{path}: no such checkpoint')
    try:
        state = torch.load(path, map_location='cpu', weights_only=True)
    except Exception as err:  # torch raises many types for bad bytes
        raise CheckpointError(
            f'{path}: not a readable checkpoint (weights-only torch.load '
            f'failed: {type(err).__name__}: {str(err)[:300]})') from err
    if not isinstance(state, dict):
        raise CheckpointError(f'{path}: a checkpoint holds a dict, found '
                              f'{type(state).__name__}')
    return state
