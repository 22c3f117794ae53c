"""WGSE's Triton kernels compiled ahead of time for real GPUs, no GPU needed.

``triton.compile`` with a ``GPUTarget`` runs triton's whole pipeline and the
``ptxas`` of the triton wheel, so it works on a machine without a GPU or a
driver; ``cuobjdump --dump-resource-usage`` (also in the wheel) then reads
each cubin's registers per thread, spill stack and static shared memory.
From those, the dynamic shared memory triton asks for and the launch's warps,
:func:`programs_per_sm` says how many programs of a variant an SM holds at
once (its occupancy). Each row also counts the values the kernel's streaming
loop carries from one step to the next in triton's IR
(:func:`loop_carried`): triton carries a name only if one pass over the
loop body changes its value, which the interpreter does not model.

Every variant the dispatcher can launch is compiled: forward and backward
(with and without the input gradient), each precision of
:data:`~wgse_mmseg.core.wgse.triton_band_networks.TOLERANCES`, each width of
``HIDDEN_CHANNELS`` and each launch entry, for sm_80 (A100), sm_89 (L40,
RTX 4090) and sm_90 (H100), at the longest band of the default WGSE at
``T = 129`` (:data:`BAND_LENGTH`; the loop over the band is not unrolled,
so the length does not change the resources).

Triton's interpreter (``TRITON_INTERPRET=1``) replaces the kernels by
Python functions that cannot be compiled, so the compiles run in a fresh
process with it unset: ``python -m wgse_mmseg.benchmarks.triton_resources``
(what :func:`compile_all` starts). Table: docs/wgse_speed.md.
"""
import argparse
import concurrent.futures
import json
import os
import re
import subprocess
import sys
import tempfile
from typing import Dict, List, NamedTuple, Optional, Sequence

from ..core.arguments import Choice, Integer
from ..core.limits import MAX_WORKERS

__all__ = []

#: target name -> (compute capability, registers per SM, most warps per SM,
#: most programs per SM, shared memory per SM in bytes, most per program)
ARCHITECTURES = {
    'sm_80': (80, 65536, 64, 32, 164 * 1024, 163 * 1024),
    'sm_89': (89, 65536, 48, 24, 100 * 1024, 99 * 1024),
    'sm_90': (90, 65536, 64, 32, 228 * 1024, 227 * 1024),
}
#: the longest band of WGSE's default (db8, 5 levels) at T = 129
BAND_LENGTH = 72
#: registers are allocated per warp in units of this many
_REGISTER_UNIT = 256
#: shared memory the CUDA runtime reserves per program (sm_80 and later)
_RESERVED_SHARED = 1024

_POINTERS = ['w1_ptr', 'b1_ptr', 'w2_ptr', 'b2_ptr', 'w3_ptr', 'b3_ptr']
_SIGNATURES = {
    'band_forward': ['x_ptr', 'y_ptr'],
    'band_backward': ['x_ptr', 'gy_ptr', 'gx_ptr', 'partial_ptr'],
}


class Variant(NamedTuple):
    """One compiled kernel: name, hidden width, precision, whether it
    computes the input gradient (``None`` for the forward), the launch
    entry's ``block``, ``num_warps`` and ``maxnreg``."""
    kernel: str
    hidden: int
    precision: str
    input_grad: Optional[bool]
    block: int
    num_warps: int
    maxnreg: Optional[int] = None

    @property
    def default(self) -> bool:
        """What runs untuned at the paper's widths: the first launch entry,
        16 or 32 channels, tensor-core precisions (not full float32)."""
        from ..core.wgse.triton_band_networks import (BACKWARD_CONFIGS,
                                                      FORWARD_CONFIGS)
        first = (FORWARD_CONFIGS if self.kernel == 'band_forward' else
                 BACKWARD_CONFIGS)[0]
        return ((self.block, self.num_warps, self.maxnreg) == first and
                self.hidden in (16, 32) and self.precision != 'ieee')


class Resources(NamedTuple):
    """What one variant uses per thread and per program on one target."""
    registers: int
    spill_bytes: int  # cuobjdump's STACK: local memory a thread needs
    local_bytes: int
    shared_bytes: int  # static + dynamic, per program
    programs_per_sm: int
    loop_carried: int  # values the loop carries to its next step


def variants() -> List[Variant]:
    """Every kernel variant the dispatcher can launch."""
    from ..core.wgse.triton_band_networks import (
        BACKWARD_CONFIGS, FORWARD_CONFIGS, HIDDEN_CHANNELS, TOLERANCES)
    found = []
    for hidden in HIDDEN_CHANNELS:
        for precision in TOLERANCES:
            found += [Variant('band_forward', hidden, precision, None, *c)
                      for c in FORWARD_CONFIGS]
            found += [Variant('band_backward', hidden, precision, grad, *c)
                      for grad in (False, True) for c in BACKWARD_CONFIGS]
    return found


def jobs_for(archs: Sequence[str]) -> List[tuple]:
    """``(variant, arch)``: every variant for each target of ``archs``."""
    return [(v, a) for a in archs for v in variants()]


def programs_per_sm(registers: int, num_warps: int, shared_bytes: int,
                    arch: str) -> int:
    """Programs of ``num_warps`` warps using ``registers`` per thread and
    ``shared_bytes`` (static + dynamic) that one SM of ``arch`` holds."""
    _, sm_registers, sm_warps, sm_programs, sm_shared, _ = \
        ARCHITECTURES[arch]
    per_warp = -(-registers * 32 // _REGISTER_UNIT) * _REGISTER_UNIT
    by_registers = (sm_registers // per_warp) // num_warps
    by_shared = sm_shared // (shared_bytes + _RESERVED_SHARED)
    return min(by_registers, sm_warps // num_warps, sm_programs, by_shared)


def loop_carried(ttir: str) -> int:
    """The number of values the ``scf.for`` loop in a kernel's triton IR
    (``compiled.asm['ttir']``) carries from one iteration to the next."""
    loops = re.findall(r'scf\.for .*? iter_args\((.*?)\) ->', ttir)
    if len(loops) != 1:
        raise ValueError(f'expected one scf.for loop in the kernel, found '
                         f'{len(loops)}')
    return loops[0].count('=')


def _cuobjdump() -> str:
    import triton
    path = os.path.join(os.path.dirname(triton.__file__), 'backends',
                        'nvidia', 'bin', 'cuobjdump')
    if not os.path.isfile(path):
        raise FileNotFoundError(f'{path}: the triton wheel ships no '
                                f'cuobjdump here')
    return path


def compile_variant(variant: Variant, arch: str) -> Resources:
    """Compile ``variant`` for ``arch`` (``'sm_90'``, ...) and read its
    resource use. Needs triton with ``TRITON_INTERPRET`` unset."""
    import triton
    from triton.backends.compiler import GPUTarget
    from triton.compiler import ASTSource

    from ..core.wgse import _triton_band_kernels as kernels
    signature = {name: '*fp32' for name in _SIGNATURES[variant.kernel]}
    signature.update(stride='i32', offset='i32', pixels='i32')
    signature.update({name: '*fp32' for name in _POINTERS})
    constants = dict(LENGTH=BAND_LENGTH, HIDDEN=variant.hidden,
                     BLOCK=variant.block, PRECISION=variant.precision)
    if variant.input_grad is not None:
        constants['INPUT_GRAD'] = variant.input_grad
    signature.update({name: 'constexpr' for name in constants})
    source = ASTSource(fn=getattr(kernels, variant.kernel),
                       signature=signature, constexprs=constants)
    compiled = triton.compile(
        source, target=GPUTarget('cuda', ARCHITECTURES[arch][0], 32),
        options=dict(num_warps=variant.num_warps, maxnreg=variant.maxnreg))
    with tempfile.NamedTemporaryFile(suffix='.cubin') as cubin:
        cubin.write(compiled.asm['cubin'])
        cubin.flush()
        dump = subprocess.run([_cuobjdump(), '--dump-resource-usage',
                               cubin.name], capture_output=True, text=True,
                              check=True).stdout
    match = re.search(r'REG:(\d+) STACK:(\d+) SHARED:(\d+) LOCAL:(\d+)',
                      dump)
    if match is None:
        raise RuntimeError(f'cuobjdump printed no resource usage for '
                           f'{variant} on {arch}:\n{dump}')
    registers, stack, static, local = map(int, match.groups())
    shared = static + compiled.metadata.shared
    return Resources(registers, stack, local, shared,
                     programs_per_sm(registers, variant.num_warps, shared,
                                     arch),
                     loop_carried(compiled.asm['ttir']))


def _compile_row(job) -> Dict:
    variant, arch = job
    return dict(arch=arch, **variant._asdict(), default=variant.default,
                **compile_variant(variant, arch)._asdict())


def _compile_here(archs: Sequence[str], jobs: int) -> List[Dict]:
    with concurrent.futures.ProcessPoolExecutor(jobs) as pool:
        return list(pool.map(_compile_row, jobs_for(archs)))


def compile_all(archs: Sequence[str] = tuple(ARCHITECTURES),
                jobs: Optional[int] = None) -> List[Dict]:
    """One row per variant and target (:func:`jobs_for`): the variant's
    fields, ``arch``, ``default`` and the :class:`Resources`. Runs in a
    fresh process with ``TRITON_INTERPRET`` unset, ``jobs`` compiles side by
    side (default: the CPUs)."""
    env = {k: v for k, v in os.environ.items() if k != 'TRITON_INTERPRET'}
    command = [sys.executable, '-m', __name__, '--json', '--jobs',
               str(jobs or os.cpu_count() or 1), '--archs', *archs]
    proc = subprocess.run(command, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f'compiling the Triton kernels failed:\n'
                           f'{proc.stderr}')
    return json.loads(proc.stdout)


def format_table(rows: Sequence[Dict]) -> str:
    """The rows as a Markdown table, defaults marked with ``*``."""
    lines = ['| arch | kernel | H | precision | input grad | block | warps '
             '| registers | spills B | shared B | programs/SM |',
             '|---|---|--:|---|---|--:|--:|--:|--:|--:|--:|']
    for r in rows:
        grad = '' if r['input_grad'] is None else str(r['input_grad'])
        cap = '' if r['maxnreg'] is None else f" r{r['maxnreg']}"
        lines.append(
            f"| {r['arch']} | {r['kernel']}{' *' if r['default'] else ''} "
            f"| {r['hidden']} | {r['precision']} | {grad} | {r['block']} | "
            f"{r['num_warps']}{cap} | "
            f"{r['registers']} | {r['spill_bytes']} | "
            f"{r['shared_bytes']} | {r['programs_per_sm']} |")
    return '\n'.join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Compile every WGSE Triton kernel variant for GPU '
        'targets (no GPU needed) and print registers, spills, shared memory '
        'and programs per SM.')
    parser.add_argument('--archs', nargs='+',
                        type=Choice(list(ARCHITECTURES)),
                        default=list(ARCHITECTURES),
                        help=f'of {list(ARCHITECTURES)} (default: all)')
    parser.add_argument('--jobs', type=Integer(1, MAX_WORKERS),
                        default=min(os.cpu_count() or 1, MAX_WORKERS))
    parser.add_argument('--json', action='store_true',
                        help='print the rows as JSON instead of a table')
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if os.environ.get('TRITON_INTERPRET', '0') not in ('', '0'):
        parser.error('unset TRITON_INTERPRET: the interpreter\'s kernels '
                     'cannot be compiled')
    rows = _compile_here(args.archs, args.jobs)
    print(json.dumps(rows) if args.json else format_table(rows))
    return 0


if __name__ == '__main__':
    sys.exit(main())
