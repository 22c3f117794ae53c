"""Peak memory and time of a WGSE training pass on the CPU backends, beside
another checkout's (an older commit's) in the same run.

Each measurement runs in a fresh process with glibc returning large
allocations to the system at once (:data:`ENVIRONMENT`), which makes the
peak repeat within about 1%: one small forward+backward first (imports,
thread pools, the transform's matrices: fixed costs, not per pixel),
then one at ``shape``
whose growth of peak RSS (``resource.getrusage``'s ``ru_maxrss``) is
divided by its pixels, then ``repeat`` more, timed.

``python -m wgse_bench.wgse_memory [--baseline CHECKOUT]`` prints one row
per backend and checkout; ``CHECKOUT`` is a work tree of another commit
(``git worktree add /tmp/old COMMIT``, with the C extensions copied or
built there), imported in place of this one.
"""
import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from typing import Dict, List, Optional

__all__ = []

#: glibc: allocations from 128 KiB up are mapped and returned at once, one
#: arena
ENVIRONMENT = dict(MALLOC_MMAP_THRESHOLD_='131072', MALLOC_ARENA_MAX='1')
SHAPE = (1, 129, 128, 128)
BACKENDS = ('compiled', 'torch')
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def worker(backend: str, shape: List[int], repeat: int) -> Dict:
    """One backend's figures, in this (fresh) process."""
    import torch

    from wgse_mmseg.core.wgse import WGSE
    torch.manual_seed(0)
    model = WGSE(backend=backend)
    small = (torch.rand(1, shape[1], 4, 4) < 0.3).float()
    model(small).sum().backward()
    model.zero_grad(set_to_none=True)
    generator = torch.Generator().manual_seed(1)
    spikes = (torch.rand(shape, generator=generator) < 0.3).float()
    grad = torch.randn(shape, generator=generator)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    model(spikes).backward(grad)
    growth = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss -
              before) * 1024  # bytes
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


def build_parser() -> argparse.ArgumentParser:
    from wgse_mmseg.command_line import Integer, Path, Text
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--baseline', type=Path(exists='directory'),
                        help='a work tree of another commit')
    parser.add_argument('--shape', type=Text(empty=False),
                        default='x'.join(map(str, SHAPE)),
                        help='BxTxHxW of the training pass')
    parser.add_argument('--repeat', type=Integer(1, 1000), default=3,
                        help='timed passes per backend')
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ['--worker'] and len(argv) == 4:
        # the driver's own call of a fresh process: backend, shape, repeat
        backend, shape, repeat = argv[1:]
        print(json.dumps(worker(backend, [int(s) for s in shape.split('x')],
                                int(repeat))))
        return 0
    args = build_parser().parse_args(argv)
    shape = [int(s) for s in args.shape.split('x')]
    checkouts = [('this checkout', ROOT)]
    if args.baseline:
        checkouts.append((args.baseline, os.path.abspath(args.baseline)))
    print(f'WGSE forward+backward at {args.shape}, {ENVIRONMENT}')
    print(f'{"checkout":<24} {"backend":<9} {"KB/pixel":>9} '
          f'{"median s":>9}')
    for backend in BACKENDS:
        for name, path in checkouts:
            res = measure(backend, shape, args.repeat, path)
            print(f'{name:<24} {res["backend"]:<9} '
                  f'{res["kb_per_pixel"]:>9.2f} {res["median_s"]:>9.3f}')
    return 0


if __name__ == '__main__':
    # run as a file by :func:`measure`: this folder's modules (``markdown``,
    # ``timing``) must not shadow installed ones
    if sys.path[0] == os.path.dirname(os.path.abspath(__file__)):
        del sys.path[0]
    sys.exit(main())
