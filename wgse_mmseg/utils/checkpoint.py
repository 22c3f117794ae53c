"""Reading checkpoint files that come from anywhere: weights only, and a
clear error naming the file for anything that is not a checkpoint, a
``state_dict`` that is not a mapping of names to tensors, or a
``dataset_meta`` that is not class names and a palette."""
import os.path as osp
import re
from typing import Dict

import numpy as np
import torch

from ..errors import WgseError, cut, excerpt
from ..fileio.input_guard import note_input

__all__ = []


class CheckpointError(WgseError, ValueError):
    """A file that cannot be read as a checkpoint; names the file."""


def load_error(err: BaseException) -> str:
    """What torch said when it refused or failed to load a checkpoint, for
    a message, without its advice to load with ``weights_only=False`` or
    to allowlist globals (which would run code from the file): for a
    weights-only refusal, the reason alone (``Unsupported global: ...``);
    otherwise its first 300 characters less such sentences."""
    text = str(err)
    found = re.search(r'WeightsUnpickler error:\s*(.*?)\s*(?:Check the '
                      r'documentation|$)', text, re.DOTALL)
    if found:
        text = found.group(1)
    sentences = re.split(r'(?<=\.)\s+', ' '.join(text.split()))
    kept = [s for s in sentences if not re.search(
        r'weights_only|safe_globals|trusted source|file an issue', s)]
    return f'{type(err).__name__}: ' + cut(' '.join(kept) or 'refused', 300)


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
    note_input(path)
    try:
        state = torch.load(path, map_location='cpu', weights_only=True)
    except Exception as err:  # torch raises many types for bad bytes
        raise CheckpointError(
            f'{path}: not a readable checkpoint (weights-only torch.load '
            f'failed: {load_error(err)})') from err
    if not isinstance(state, dict):
        raise CheckpointError(f'{path}: a checkpoint holds a dict, found '
                              f'{type(state).__name__}')
    return state


def checkpoint_state_dict(path: str, state: dict) -> Dict[str, torch.Tensor]:
    """The ``state_dict`` of a checkpoint ``state`` read from ``path`` (or
    ``state`` itself where it has none, a bare state dict): a mapping of
    parameter names (str) to tensors.

    Raises:
        CheckpointError: naming ``path`` and the first entry that is not a
            name and a tensor.
    """
    weights = state.get('state_dict', state)
    if not isinstance(weights, dict):
        raise CheckpointError(f'{path}: state_dict must map parameter names '
                              f'to tensors, found {type(weights).__name__}')
    for name, value in weights.items():
        if not isinstance(name, str) or not isinstance(value, torch.Tensor):
            raise CheckpointError(
                f'{path}: state_dict must map parameter names (str) to '
                f'tensors, found {excerpt(name, 100)} -> '
                f'{type(value).__name__}')
    return weights


def check_dataset_meta(source: str, meta) -> dict:
    """``meta`` as ``dict(classes=[str, ...], palette=[[R, G, B], ...])``:
    class names, as many as palette rows of three integers in 0..255.

    Raises:
        CheckpointError: naming ``source`` (a file) and the field that is
            not so.
    """
    if not isinstance(meta, dict):
        raise CheckpointError(
            f'{source}: dataset_meta must be a mapping with classes and '
            f'palette, got {type(meta).__name__}')
    classes, palette = meta.get('classes'), meta.get('palette')
    if not isinstance(classes, (list, tuple)) or not classes or not all(
            isinstance(c, str) for c in classes):
        raise CheckpointError(
            f'{source}: dataset_meta classes must be a non-empty list of '
            f'names (str), got {excerpt(classes)}')
    if not isinstance(palette, (list, tuple)):
        raise CheckpointError(
            f'{source}: dataset_meta palette must be a list of [R, G, B] '
            f'rows, got {type(palette).__name__}')
    for index, row in enumerate(palette):
        if not (isinstance(row, (list, tuple)) and len(row) == 3 and all(
                isinstance(v, (int, np.integer)) and
                not isinstance(v, (bool, np.bool_)) and 0 <= v <= 255
                for v in row)):
            raise CheckpointError(
                f'{source}: dataset_meta palette row {index} is '
                f'{excerpt(row, 100)}; each row is three integers in 0..255')
    if len(palette) != len(classes):
        raise CheckpointError(
            f'{source}: dataset_meta has {len(classes)} classes but '
            f'{len(palette)} palette rows; one colour per class')
    return dict(classes=list(classes),
                palette=[[int(v) for v in row] for row in palette])
