"""Peak memory and time of a WGSE training pass on the CPU backends, beside
another checkout's (an older commit's), interleaved in one run.

Each measurement runs in a fresh process with glibc returning large
allocations to the system at once (:data:`ENVIRONMENT`), which makes the
peak repeat within about 1%: one small forward+backward first, given an
output gradient as the measured pass is (imports, thread pools, the
transform's matrices and what autograd's first call with a given gradient
imports: fixed costs, not per pixel), then one at ``shape`` whose peak
resident set over the resident set before it (Linux: the high-water mark
reset to the current size just before, so that the warm-up's own peak
cannot hide it) is divided by its pixels, then ``repeat`` more, timed.

The run takes ``rounds`` rounds; each runs every backend in every checkout,
the checkouts' order alternating from round to round, so that a change in
the machine's load reaches both alike. A row's figures are medians over the
rounds (a round's time: the median of its ``repeat`` passes); its ratios to
the baseline are the medians of the rounds' ratios.

``python -m wgse_bench.wgse_memory [--baseline CHECKOUT]`` prints one row
per backend and checkout, with the machine and its load average before
and after; ``CHECKOUT`` is a work tree of another commit (``git worktree
add DIR COMMIT``, with the C extensions built there: ``python setup.py
build_ext --inplace``), imported in place of this one.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from typing import Dict, List, Optional, Sequence

__all__ = []

#: glibc: allocations from 128 KiB up are mapped and returned at once, one
#: arena
ENVIRONMENT = dict(MALLOC_MMAP_THRESHOLD_='131072', MALLOC_ARENA_MAX='1')
SHAPE = (1, 129, 128, 128)
BACKENDS = ('compiled', 'torch')
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _status_kib(field: str) -> int:
    """``field`` (``'VmRSS'``, ``'VmHWM'``) of ``/proc/self/status``, KiB."""
    with open('/proc/self/status') as f:
        for line in f:
            if line.startswith(field + ':'):
                return int(line.split()[1])
    raise RuntimeError(f'/proc/self/status has no {field} line')


def _reset_peak() -> None:
    """Set the resident set's high-water mark to its current size
    (``/proc/self/clear_refs``, Linux 4.0 on)."""
    with open('/proc/self/clear_refs', 'w') as f:
        f.write('5')


def worker(backend: str, shape: List[int], repeat: int) -> Dict:
    """One backend's figures, in this (fresh) process: ``kb_per_pixel``
    (KB = 1000 bytes), ``median_s`` of the ``repeat`` timed passes."""
    import torch

    from wgse_mmseg.core.wgse import WGSE
    torch.manual_seed(0)
    model = WGSE(backend=backend)
    small = (torch.rand(1, shape[1], 4, 4) < 0.3).float()
    model(small).backward(torch.randn_like(small))
    model.zero_grad(set_to_none=True)
    generator = torch.Generator().manual_seed(1)
    spikes = (torch.rand(shape, generator=generator) < 0.3).float()
    grad = torch.randn(shape, generator=generator)
    before = _status_kib('VmRSS')
    _reset_peak()
    model(spikes).backward(grad)
    growth = (_status_kib('VmHWM') - before) * 1024  # bytes
    times = []
    for _ in range(repeat):
        model.zero_grad(set_to_none=True)
        start = time.perf_counter()
        model(spikes).backward(grad)
        times.append(time.perf_counter() - start)
    pixels = shape[0] * shape[2] * shape[3]
    return dict(backend=model.backend_in_use,
                kb_per_pixel=growth / 1000 / pixels,
                median_s=statistics.median(times))


def measure(backend: str, shape: List[int], repeat: int,
            checkout: str = ROOT) -> Dict:
    """:func:`worker` in a fresh process importing ``checkout``'s
    ``wgse_mmseg``."""
    env = dict(os.environ, **ENVIRONMENT, PYTHONPATH=checkout)
    cmd = [sys.executable, os.path.abspath(__file__), '--worker', backend,
           'x'.join(map(str, shape)), str(repeat)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f'{cmd} failed:\n{proc.stderr}')
    return json.loads(proc.stdout.strip().splitlines()[-1])


def summarize(rounds: Sequence[Dict[str, Dict]], baseline: Optional[str]
              ) -> Dict[str, Dict]:
    """Per checkout, the medians over ``rounds`` (each ``{checkout:
    measure's dict}``, one backend) of ``kb_per_pixel`` and ``median_s``,
    and, beside a ``baseline`` checkout, the medians of the rounds' ratios
    to it (``memory``, ``time``; ``None`` for the baseline itself)."""
    summary = {}
    for name in rounds[0]:
        row = {key: statistics.median(r[name][key] for r in rounds)
               for key in ('kb_per_pixel', 'median_s')}
        row['backend'] = rounds[0][name]['backend']
        for ratio, key in (('memory', 'kb_per_pixel'), ('time', 'median_s')):
            row[ratio] = None if baseline in (None, name) else \
                statistics.median(r[name][key] / r[baseline][key]
                                  for r in rounds)
        summary[name] = row
    return summary


def _commit(checkout: str) -> str:
    """``checkout``'s commit (short; ``+`` where its work tree differs),
    or its path where git cannot say."""
    git = ['git', '-C', checkout]
    head = subprocess.run(git + ['rev-parse', '--short', 'HEAD'],
                          capture_output=True, text=True)
    if head.returncode != 0:
        return checkout
    changes = subprocess.run(git + ['status', '--porcelain',
                                    '--untracked-files=no'],
                             capture_output=True, text=True)
    return head.stdout.strip() + ('+' if changes.stdout.strip() else '')


def build_parser() -> argparse.ArgumentParser:
    from wgse_mmseg.command_line import Integer, Path, Text
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--baseline', type=Path(exists='directory'),
                        help='a work tree of another commit')
    parser.add_argument('--shape', type=Text(empty=False),
                        default='x'.join(map(str, SHAPE)),
                        help='BxTxHxW of the training pass')
    parser.add_argument('--repeat', type=Integer(1, 1000), default=3,
                        help='timed passes per backend and process')
    parser.add_argument('--rounds', type=Integer(1, 100), default=3,
                        help='fresh processes per backend and checkout, '
                        'the checkouts interleaved')
    return parser


def _load() -> str:
    return '/'.join(f'{value:.2f}' for value in os.getloadavg())


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ['--worker'] and len(argv) == 4:
        # the driver's own call of a fresh process: backend, shape, repeat
        backend, shape, repeat = argv[1:]
        print(json.dumps(worker(backend, [int(s) for s in shape.split('x')],
                                int(repeat))))
        return 0
    args = build_parser().parse_args(argv)
    from wgse_bench.machine import machine_record
    shape = [int(s) for s in args.shape.split('x')]
    checkouts = {f'this checkout ({_commit(ROOT)})': ROOT}
    baseline = None
    if args.baseline:
        path = os.path.abspath(args.baseline)
        baseline = _commit(path)
        checkouts[baseline] = path
    machine = machine_record()
    print(f'WGSE forward+backward at {args.shape}, {ENVIRONMENT}; '
          f'{machine["cpu"]}, {machine["cpu_count"]} CPUs, '
          f'{machine["torch_threads"]} torch threads, torch '
          f'{machine["torch"]}; load average {_load()} (1/5/15 min) '
          f'before')
    print(f'{args.rounds} rounds, the checkouts interleaved; medians over '
          f'the rounds, ratios to {baseline or "no baseline"} per round')
    print(f'{"checkout":<26} {"backend":<9} {"KB/pixel":>9} '
          f'{"memory":>7} {"median s":>9} {"time":>6}')
    names = list(checkouts)
    for backend in BACKENDS:
        rounds = []
        for index in range(args.rounds):
            order = names if index % 2 == 0 else names[::-1]
            rounds.append({name: measure(backend, shape, args.repeat,
                                         checkouts[name])
                           for name in order})
        for name, row in summarize(rounds, baseline).items():
            memory, speed = (
                '' if row[key] is None else f'{row[key]:.2f}x'
                for key in ('memory', 'time'))
            print(f'{name:<26} {row["backend"]:<9} '
                  f'{row["kb_per_pixel"]:>9.2f} {memory:>7} '
                  f'{row["median_s"]:>9.3f} {speed:>6}')
    print(f'load average {_load()} after')
    return 0


if __name__ == '__main__':
    # run as a file by :func:`measure`: this folder's modules (``markdown``,
    # ``timing``) must not shadow installed ones
    if sys.path[0] == os.path.dirname(os.path.abspath(__file__)):
        del sys.path[0]
    sys.exit(main())
