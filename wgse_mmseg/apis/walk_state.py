"""The resume state of a walk (:mod:`.recording_walk`): its settings and
its progress file, one row a window with the size and SHA-256 of the frame
it wrote, trusted only as far as the frames on disk verify.
"""
import json
import os
import os.path as osp
from typing import Any, List, Sequence

from ..fileio.atomic import atomic_output, write_bytes
from ..fileio.bounded_reads import load_json_file
from ..fileio.markers import file_digest
from ..fileio.output_folder import OwnedFolder
from .walk_plan import WalkError, WalkPlan

#: the CSV's columns, one row per walked window
CSV_COLUMNS = ('window', 'centre', 'start', 'end', 'batch', 'time_ms')


_SETTINGS = 'settings.json'


PROGRESS_NAME = 'progress.csv'


#: a row of ``progress.csv``: the CSV's, then the size and SHA-256 of the
#: window's PNG as written
_PROGRESS_COLUMNS = CSV_COLUMNS + ('size', 'sha256')


#: the longest row ``progress.csv`` holds (a longer one is damage)
_ROW_BYTES = 256


def frame_name(index: int) -> str:
    return f'{index:06d}.png'


def _frame_verifies(state: OwnedFolder, index: int, size: str,
                    sha256: str) -> bool:
    """Whether window ``index``'s PNG is a regular file holding the
    ``size`` bytes of SHA-256 ``sha256`` its row records."""
    path = state.file(osp.join(state.root, frame_name(index)))
    return (osp.exists(path) and str(os.stat(path).st_size) == size
            and file_digest(path) == sha256)


def _windows_done(state: OwnedFolder, plan: WalkPlan) -> int:
    """How many leading rows of ``progress.csv`` are complete, in order,
    match ``plan`` and have their PNG as recorded; the file is rewritten
    (a new file, whatever was at its path) with just them."""
    progress = state.file(osp.join(state.root, PROGRESS_NAME))
    done = 0
    with atomic_output(progress) as kept:
        if osp.exists(progress):
            with open(progress, 'rb') as f:
                for line in iter(lambda: f.readline(_ROW_BYTES), b''):
                    row = line.decode('utf-8', 'replace').rstrip('\n')
                    row = row.split(',')
                    if (not line.endswith(b'\n')  # torn by an interruption
                            or len(row) != len(_PROGRESS_COLUMNS)
                            or done >= len(plan.centres)
                            or row[:4] != _row_start(plan, done)
                            or not _frame_verifies(state, done, *row[-2:])):
                        break
                    kept.write(line)
                    done += 1
    return done


def _row_start(plan: WalkPlan, index: int) -> List[str]:
    """The first columns of window ``index``'s row: index, centre, start,
    end."""
    centre = plan.centres[index]
    return [str(index), str(centre), str(plan.start(centre)),
            str(plan.start(centre) + plan.length)]


def csv_line(row: Sequence[Any]) -> bytes:
    """One CSV row of numbers (or the header), ``\n``-terminated."""
    return (','.join(map(str, row)) + '\n').encode()


def open_state(state: OwnedFolder, identity: dict, plan: WalkPlan) -> int:
    """The state folder, checked against ``identity`` or started afresh
    (when empty, or its settings file cannot be read); the number of
    windows already done."""
    settings = state.file(osp.join(state.root, _SETTINGS))
    recorded = None
    if osp.exists(settings):
        try:
            recorded = load_json_file(settings, 'walk settings file')
        except (OSError, ValueError):
            pass  # damaged: nothing in the folder can be trusted
    if recorded is None:
        state.clear()
        write_bytes(osp.join(state.root, PROGRESS_NAME), b'')
        write_bytes(settings, json.dumps(identity, indent=1).encode())
        return 0
    if recorded != identity:
        keys = sorted(set(identity) | set(recorded if isinstance(
            recorded, dict) else {}))
        changed = [k for k in keys if not isinstance(recorded, dict)
                   or recorded.get(k) != identity.get(k)]
        raise WalkError(
            f'{state.root}: holds an interrupted walk with other '
            f'settings ({", ".join(changed)} differ: '
            f'{_differences(recorded, identity, changed)}); its frames '
            f'are not mixed with these: re-run with its settings to '
            f'finish it, or remove the folder to start over')
    return _windows_done(state, plan)


def _differences(recorded: Any, identity: dict, keys: List[str]) -> str:
    if not isinstance(recorded, dict):
        return 'the recorded settings are not a mapping'
    return '; '.join(f'{k} was {str(recorded.get(k))[:80]}, now '
                     f'{str(identity.get(k))[:80]}' for k in keys)
