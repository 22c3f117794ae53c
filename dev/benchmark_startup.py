"""Start-up time of every command line, and what it imports before it answers.

    python dev/benchmark_startup.py [--repeat 5] [--out F]

For every Python tool under ``tools/``: wall seconds of ``python TOOL
--help`` and of an argument error (``python TOOL --no-such-option``), each
the median of ``--repeat`` fresh processes, and the heavy modules
(:data:`HEAVY`: torch, OpenMMLab, Triton, ONNX, OpenCV) the ``--help``
process imported (read from ``python -X importtime``). Then, for reference,
the same for ``import torch``, ``import wgse_mmseg`` and
``wgse_mmseg.register_all_modules()``. Prints a Markdown table under the
machine it ran on. The checkout this script is in is measured
(``PYTHONPATH`` is set to it).
"""
import argparse
import json
import os
import os.path as osp
import statistics
import subprocess
import sys
import time
from typing import Dict, List, Sequence

from wgse_mmseg.command_line import Integer, Path
from wgse_mmseg.limits import MAX_REPEAT
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.fileio.input_guard import keeps_inputs

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: the modules a tool's --help must not need: each takes from a tenth of a
#: second (OpenCV) to two (torch) to import
HEAVY = ('torch', 'mmengine', 'mmseg', 'mmcv', 'triton', 'onnx',
         'onnxruntime', 'cv2')
#: label -> Python statement, the references
STATEMENTS = {
    'import torch': 'import torch',
    'import wgse_mmseg': 'import wgse_mmseg',
    'register_all_modules()':
        'import wgse_mmseg; wgse_mmseg.register_all_modules()',
}


def tools() -> List[str]:
    """The Python tools under ``tools/`` and ``dev/``, relative to the
    checkout."""
    found = []
    for room in ('tools', 'dev'):
        for folder, _, files in os.walk(osp.join(ROOT, room)):
            found += [osp.relpath(osp.join(folder, name), ROOT)
                      for name in files if name.endswith('.py')]
    return sorted(found)


def _environment() -> Dict[str, str]:
    return dict(os.environ, PYTHONPATH=ROOT)


def _seconds(command: Sequence[str]) -> float:
    began = time.perf_counter()
    subprocess.run(command, cwd=ROOT, env=_environment(),
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - began


def heavy_imports(arguments: Sequence[str]) -> List[str]:
    """The :data:`HEAVY` modules ``python ARGUMENTS`` imports (``-X
    importtime``), in :data:`HEAVY`'s order. Raises ``RuntimeError`` where
    the process fails (an argument error's status 2 aside)."""
    proc = subprocess.run([sys.executable, '-X', 'importtime', *arguments],
                          cwd=ROOT, env=_environment(), capture_output=True,
                          text=True)
    if proc.returncode not in (0, 2):
        raise RuntimeError(f'python {" ".join(arguments)} failed:\n'
                           f'{proc.stderr[-2000:]}')
    imported = {line.rsplit('|', 1)[-1].strip().split('.')[0]
                for line in proc.stderr.splitlines()
                if line.startswith('import time:')}
    return [name for name in HEAVY if name in imported]


def measure(repeat: int) -> List[Dict]:
    """One row per tool, then per statement of :data:`STATEMENTS`."""
    rows = []
    for tool in tools():
        help_s = [_seconds([sys.executable, tool, '--help'])
                  for _ in range(repeat)]
        error_s = [_seconds([sys.executable, tool, '--no-such-option'])
                   for _ in range(repeat)]
        rows.append(dict(command=tool, help_s=statistics.median(help_s),
                         error_s=statistics.median(error_s),
                         imports=heavy_imports([tool, '--help'])))
    for label, statement in STATEMENTS.items():
        seconds = [_seconds([sys.executable, '-c', statement])
                   for _ in range(repeat)]
        rows.append(dict(command=label, help_s=statistics.median(seconds),
                         error_s=None,
                         imports=heavy_imports(['-c', statement])))
    return rows


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=Integer(1, MAX_REPEAT), default=5,
                        help='fresh processes per measurement (default 5)')
    parser.add_argument('--out', type=Path(),
                        help='also write the rows and the machine as JSON')
    return parser


@keeps_inputs
def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    check_tool_outputs(args, 'out')
    from wgse_bench.machine import machine_record
    from wgse_bench.markdown import markdown_table
    from wgse_mmseg.fileio.atomic import atomic_output
    before = os.getloadavg()[0]
    rows = measure(args.repeat)
    machine = machine_record('cpu')
    print(f'{machine["cpu"]}, {machine["cpu_count"]} CPUs, load average '
          f'{before:.2f} before, {machine["load_average"]:.2f} after; '
          f'Python {machine["python"]}, torch {machine["torch"]}, '
          f'mmengine {machine["mmengine"]}; median of {args.repeat} '
          f'processes\n')
    print(markdown_table(
        ['command', '--help (s)', 'argument error (s)', 'heavy imports'],
        [(row['command'], f'{row["help_s"]:.2f}',
          '' if row['error_s'] is None else f'{row["error_s"]:.2f}',
          ', '.join(row['imports']) or 'none') for row in rows]))
    if args.out:
        with atomic_output(args.out) as f:
            f.write(json.dumps(dict(machine=machine, repeat=args.repeat,
                                    rows=rows), indent=2).encode())
        print(f'\nwritten to {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
