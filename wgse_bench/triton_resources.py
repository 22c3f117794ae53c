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
:data:`~wgse_mmseg.core.kernel_choices.TOLERANCES`, each width of
``HIDDEN_CHANNELS`` and each launch entry of the target, for sm_80 (A100),
sm_89 (L40, RTX 4090), sm_90 (H100, H200), sm_100 (B200) and sm_120 (RTX
5090, RTX PRO 6000). Band lengths are run-time values of the kernels, so
one compile serves every band.

The cost model (:func:`step_cost`) reads the compiled code: the
instructions of the loop over a band's coefficients (the step every
coefficient of a tile takes), all and tensor-core ones (``HMMA``,
``HGMMA``, sm_100's ``UTCHMMA``), as warp instructions per coefficient
position (times the warps, over the pixels of a tile); what that count
leaves out, and what it predicts of a GPU's time, is
:mod:`.kernel_prediction`'s.

Triton's interpreter (``TRITON_INTERPRET=1``) replaces the kernels by
Python functions that cannot be compiled, so the compiles run in a fresh
process with it unset: ``python -m wgse_bench.triton_resources``
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
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple

from wgse_mmseg.command_line import Choice, Integer
from wgse_mmseg.limits import MAX_WORKERS

from . import sass_timing

__all__ = []

#: target name -> (compute capability, registers per SM, most warps per SM,
#: most programs per SM, shared memory per SM in bytes, most per program)
ARCHITECTURES = {
    'sm_80': (80, 65536, 64, 32, 164 * 1024, 163 * 1024),
    'sm_89': (89, 65536, 48, 24, 100 * 1024, 99 * 1024),
    'sm_90': (90, 65536, 64, 32, 228 * 1024, 227 * 1024),
    'sm_100': (100, 65536, 64, 32, 228 * 1024, 227 * 1024),
    'sm_120': (120, 65536, 48, 32, 100 * 1024, 99 * 1024),
}
#: registers are allocated per warp in units of this many
_REGISTER_UNIT = 256
#: shared memory the CUDA runtime reserves per program (sm_80 and later)
_RESERVED_SHARED = 1024

#: the six parameter pointers every band kernel takes, conv1 to conv3
POINTERS = ['w1_ptr', 'b1_ptr', 'w2_ptr', 'b2_ptr', 'w3_ptr', 'b3_ptr']
_SIGNATURES = {
    'band_forward': dict(x_ptr='*fp32', out_ptr='*fp32', mask_ptr='*u8',
                         pixels='i32', columns='i32',
                         tiles_per_sample='i32', lengths_ptr='*i32',
                         offsets_ptr='*i32'),
    'band_backward': dict(x_ptr='*fp32', d3_ptr='*fp32', gx_ptr='*fp32',
                          partial_ptr='*fp32', work_ptr='*i32',
                          pixels='i32', columns='i32',
                          tiles_per_sample='i32', tiles='i32',
                          lengths_ptr='*i32', offsets_ptr='*i32'),
}


class Variant(NamedTuple):
    """One compiled kernel: name, hidden width, precision, whether it
    computes the input gradient (the forward: never), the launch entry's
    ``block``, ``num_warps`` and
    ``maxnreg``."""
    kernel: str
    hidden: int
    precision: str
    input_grad: bool
    block: int
    num_warps: int
    maxnreg: Optional[int] = None

    @property
    def tensor_cores(self) -> bool:
        """Whether its products run on tensor cores: every precision but
        full float32 (``'ieee'``, where TF32 is turned off), which
        multiplies on the FMA units and may spill."""
        return self.precision != 'ieee'


class Resources(NamedTuple):
    """What one variant uses per thread and per program on one target."""
    registers: int
    spill_bytes: int  # cuobjdump's STACK: local memory a thread needs
    local_bytes: int
    shared_bytes: int  # static + dynamic, per program
    programs_per_sm: int
    loop_carried: int  # values the loops carry to their next step
    step_instructions: int  # warp instructions of the step loop, a warp
    step_tensor_core: int  # of which HMMA/HGMMA


def variants() -> List[Variant]:
    """Every kernel variant the dispatcher can launch (the same on every
    target)."""
    from wgse_mmseg.core.kernel_choices import HIDDEN_CHANNELS, TOLERANCES
    from wgse_mmseg.core.wgse.triton_launch_choices import (FORWARD_CONFIGS,
                                                            backward_configs)
    found = []
    for hidden in HIDDEN_CHANNELS:
        for precision in TOLERANCES:
            found += [Variant('band_forward', hidden, precision, False, *c)
                      for c in FORWARD_CONFIGS]
            found += [Variant('band_backward', hidden, precision, grad, *c)
                      for grad in (False, True)
                      for c in backward_configs(grad, precision)]
    return found


def jobs_for(archs: Sequence[str]) -> List[tuple]:
    """``(variant, arch)``: every variant of each target of ``archs``."""
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
    """The number of values the ``scf.for`` loops in a kernel's triton IR
    (``compiled.asm['ttir']``) carry from one iteration to the next."""
    loops = re.findall(r'scf\.for .*? iter_args\((.*?)\) ->', ttir)
    if not loops:
        raise ValueError('expected an scf.for loop in the kernel, found none')
    return sum(loop.count('=') for loop in loops)


#: SASS opcodes of the tensor cores' matrix products
TENSOR_CORE_OPCODES = ('HMMA', 'HGMMA', 'UTCHMMA')


def step_loop(sass: str) -> List[str]:
    """The opcodes of the step loop of ``cuobjdump -sass`` text: the
    shortest range that a backward branch closes and that loads from global
    memory (the step over a band's coefficients, which loads the next ones;
    the backward kernel's loop over tiles encloses it, and on sm_100 the
    waits for the tensor cores' barriers are shorter loops that load
    nothing). A branch's target is its last operand, after a uniform
    predicate (``BRA.U UP0, 0x...``) where it has one, before the
    scheduling notes sm_120's code carries (``?trans6``)."""
    code = [sass_timing.Instruction(int(address, 16), opcode,
                                    f'{opcode} {operands}'.strip(), 0, None,
                                    None, 0)
            for address, _, opcode, operands in re.findall(
                r'/\*([0-9a-f]{4,})\*/\s+(@!?U?P\w+\s+)?([A-Z][\w.]*)'
                r'\s*([^;]*);', sass)]
    first, last = sass_timing.loop_bounds(code)
    return [ins.opcode for ins in code[first:last + 1]]


def step_cost(opcodes: Sequence[str]) -> tuple:
    """``(instructions, tensor-core instructions)`` of a step loop's
    opcodes (:func:`step_loop`)."""
    return len(opcodes), sum(op.split('.')[0] in TENSOR_CORE_OPCODES
                             for op in opcodes)


def per_position(step_instructions: int, num_warps: int, block: int
                 ) -> float:
    """Warp instructions a coefficient position costs: a step of every
    warp of a program, over the pixels of its tile."""
    return step_instructions * num_warps / block


def _cuobjdump() -> str:
    import triton
    path = os.path.join(os.path.dirname(triton.__file__), 'backends',
                        'nvidia', 'bin', 'cuobjdump')
    if not os.path.isfile(path):
        raise FileNotFoundError(f'{path}: the triton wheel ships no '
                                f'cuobjdump here')
    return path


def compile_band_kernel(fn, arguments: Dict[str, str],
                        constants: Dict[str, object], capability: int,
                        options: Dict[str, object]):
    """``(compiled kernel, its SASS text, cuobjdump's resource report)`` of
    the band kernel ``fn`` compiled by triton for compute capability
    ``capability`` (80, 90, ...): its arguments are ``arguments`` (name ->
    triton type), then the six parameter pointers :data:`POINTERS`, then
    ``constants`` (its ``constexpr`` values). Needs triton with
    ``TRITON_INTERPRET`` unset."""
    import triton
    from triton.backends.compiler import GPUTarget
    from triton.compiler import ASTSource
    signature = {**arguments, **{name: '*fp32' for name in POINTERS},
                 **{name: 'constexpr' for name in constants}}
    compiled = triton.compile(
        ASTSource(fn=fn, signature=signature, constexprs=constants),
        target=GPUTarget('cuda', capability, 32), options=options)
    dump, sass = disassemble(compiled)
    return compiled, sass, dump


def compile_and_disassemble(variant: Variant, arch: str):
    """:func:`compile_band_kernel` of ``variant`` for ``arch``."""
    from wgse_mmseg.core.wgse import triton_band_kernels as kernels
    from wgse_mmseg.core.wgse.triton_launch_choices import (
        conv1_on_tensor_cores, taps_as_one_product)
    constants = dict(HIDDEN=variant.hidden, BLOCK=variant.block,
                     PRECISION=variant.precision)
    if variant.kernel == 'band_backward':
        constants['INPUT_GRAD'] = variant.input_grad
    else:
        major = ARCHITECTURES[arch][0] // 10
        constants['CONV1_DOT'] = conv1_on_tensor_cores(variant.precision,
                                                       major)
        constants['TAPS_01_AS_ONE'] = taps_as_one_product(
            variant.precision, major)
    return compile_band_kernel(
        getattr(kernels, variant.kernel), _SIGNATURES[variant.kernel],
        constants, ARCHITECTURES[arch][0],
        dict(num_warps=variant.num_warps, maxnreg=variant.maxnreg))


def disassemble(compiled) -> Tuple[str, str]:
    """cuobjdump's resource usage and SASS of a Triton compilation's
    cubin."""
    with tempfile.NamedTemporaryFile(suffix='.cubin') as cubin:
        cubin.write(compiled.asm['cubin'])
        cubin.flush()
        dump, sass = (subprocess.run(
            [_cuobjdump(), option, cubin.name], capture_output=True,
            text=True, check=True).stdout
            for option in ('--dump-resource-usage', '--dump-sass'))
    return dump, sass


def compile_variant(variant: Variant, arch: str) -> Resources:
    """Compile ``variant`` for ``arch`` (``'sm_90'``, ...) and read its
    resource use. Needs triton with ``TRITON_INTERPRET`` unset."""
    return resources_of(variant, arch,
                        *compile_and_disassemble(variant, arch))


def resource_usage(dump: str, what: str) -> Tuple[int, int, int, int]:
    """``(registers, spill stack bytes, static shared bytes, local
    bytes)`` of cuobjdump's resource report ``dump`` of the kernel
    ``what`` (named where the report has none)."""
    match = re.search(r'REG:(\d+) STACK:(\d+) SHARED:(\d+) LOCAL:(\d+)',
                      dump)
    if match is None:
        raise RuntimeError(f'cuobjdump printed no resource usage for '
                           f'{what}:\n{dump}')
    return tuple(map(int, match.groups()))


def resources_of(variant: Variant, arch: str, compiled, sass: str,
                 dump: str) -> Resources:
    """:class:`Resources` of a :func:`compile_and_disassemble` kernel."""
    registers, stack, static, local = resource_usage(dump,
                                                     f'{variant} on {arch}')
    shared = static + compiled.metadata.shared
    return Resources(registers, stack, local, shared,
                     programs_per_sm(registers, variant.num_warps, shared,
                                     arch),
                     loop_carried(compiled.asm['ttir']),
                     *step_cost(step_loop(sass)))


def cannot_compile() -> Optional[str]:
    """Why the kernels cannot be compiled for GPUs here (no triton, or its
    wheel without ``ptxas`` or ``cuobjdump``), or ``None``."""
    try:
        from triton import knobs
        ptxas = knobs.nvidia.ptxas.path
        _cuobjdump()
    except (ImportError, FileNotFoundError, RuntimeError) as err:
        return f'triton cannot compile for GPUs here ({err})'
    return None if ptxas and os.path.isfile(ptxas) else \
        f'triton has no ptxas here ({ptxas!r})'


def training_variants(precision: str, hidden: int) -> List[Variant]:
    """The forward's and the backward's variants a training pass runs."""
    from wgse_mmseg.core.wgse.triton_launch_choices import (FORWARD_CONFIGS,
                                                            backward_configs)
    return [Variant('band_forward', hidden, precision, False,
                    *FORWARD_CONFIGS[0]),
            Variant('band_backward', hidden, precision, False,
                    *backward_configs(False, precision)[0])]


def ptxas_reports(precision: str) -> Dict[str, str]:
    """:func:`ptxas_report` of each kernel's training variant at
    ``precision`` for sm_90, by kernel name. Runs in a fresh process with
    ``TRITON_INTERPRET`` unset."""
    return run_fresh(['--ptxas', precision])


def ptxas_report(variant: Variant, arch: str) -> str:
    """What ``ptxas -v`` says of ``variant``'s PTX for ``arch`` (its
    notices, such as ``C7514``: ``wgmma`` products serialised, each waited
    for before the next; triton's own compile keeps none of it). Needs
    triton with ``TRITON_INTERPRET`` unset."""
    from triton import knobs
    compiled, _, _ = compile_and_disassemble(variant, arch)
    target = f"{arch}a" if arch in ('sm_90', 'sm_100') else arch
    tool = knobs.nvidia.ptxas_blackwell if ARCHITECTURES[arch][0] >= 100 \
        else knobs.nvidia.ptxas
    with tempfile.TemporaryDirectory() as folder:
        ptx = os.path.join(folder, 'kernel.ptx')
        with open(ptx, 'w') as f:
            f.write(compiled.asm['ptx'])
        return subprocess.run(
            [tool.path, '-v', f'--gpu-name={target}', ptx, '-o',
             os.path.join(folder, 'kernel.cubin')], capture_output=True,
            text=True, check=True).stderr


def run_fresh(arguments: Sequence[str], module: str = __name__):
    """``module``'s command line (this one's by default) run in a fresh
    process with ``TRITON_INTERPRET`` unset, its JSON output read: the
    interpreter's kernels cannot be compiled."""
    env = {k: v for k, v in os.environ.items() if k != 'TRITON_INTERPRET'}
    proc = subprocess.run([sys.executable, '-m', module, '--json',
                           *arguments], capture_output=True, text=True,
                          env=env)
    if proc.returncode != 0:
        raise RuntimeError(f'compiling the Triton kernels failed:\n'
                           f'{proc.stderr}')
    return json.loads(proc.stdout)


def _compile_row(job) -> Dict:
    variant, arch = job
    resources = compile_variant(variant, arch)
    return dict(arch=arch, **variant._asdict(),
                tensor_cores=variant.tensor_cores, **resources._asdict(),
                per_position=per_position(resources.step_instructions,
                                          variant.num_warps, variant.block),
                tensor_core_per_position=per_position(
                    resources.step_tensor_core, variant.num_warps,
                    variant.block))


def compile_rows(archs: Sequence[str], jobs: int) -> List[Dict]:
    """:func:`compile_all`'s rows, compiled in this process's pool of
    ``jobs``."""
    with concurrent.futures.ProcessPoolExecutor(jobs) as pool:
        return list(pool.map(_compile_row, jobs_for(archs)))


def compile_all(archs: Sequence[str] = tuple(ARCHITECTURES),
                jobs: Optional[int] = None) -> List[Dict]:
    """One row per variant and target (:func:`jobs_for`): the variant's
    fields, ``arch``, ``tensor_cores``, the :class:`Resources` and the
    step's warp instructions per coefficient position, all
    (``per_position``) and tensor-core ones. Runs in a
    fresh process with ``TRITON_INTERPRET`` unset, ``jobs`` compiles side by
    side (default: the CPUs)."""
    return run_fresh(['--jobs', str(jobs or os.cpu_count() or 1),
                      '--archs', *archs])


def format_table(rows: Sequence[Dict]) -> str:
    """The rows as a Markdown table; full-float32 variants (no tensor
    cores) marked with ``-``."""
    lines = ['| arch | kernel | H | precision | grad | block | warps '
             '| registers | spills B | shared B | programs/SM '
             '| step instr | TC instr | instr/position | TC/position |',
             '|---|---|--:|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|']
    for r in rows:
        cap = '' if r['maxnreg'] is None else f" r{r['maxnreg']}"
        lines.append(
            f"| {r['arch']} | {r['kernel']} | {r['hidden']} | "
            f"{r['precision']}{'' if r['tensor_cores'] else ' -'} | "
            f"{r['input_grad']} | {r['block']} | {r['num_warps']}{cap} | "
            f"{r['registers']} | {r['spill_bytes']} | "
            f"{r['shared_bytes']} | {r['programs_per_sm']} | "
            f"{r['step_instructions']} | {r['step_tensor_core']} | "
            f"{r['per_position']:.1f} | {r['tensor_core_per_position']:.2f} |")
    return '\n'.join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Compile every WGSE Triton kernel variant for GPU '
        'targets (no GPU needed) and print registers, spills, shared memory, '
        'programs per SM and the step loop\'s instructions per coefficient '
        'position (all and tensor-core).')
    parser.add_argument('--archs', nargs='+',
                        type=Choice(list(ARCHITECTURES)),
                        default=list(ARCHITECTURES),
                        help=f'of {list(ARCHITECTURES)} (default: all)')
    parser.add_argument('--jobs', type=Integer(1, MAX_WORKERS),
                        default=min(os.cpu_count() or 1, MAX_WORKERS))
    parser.add_argument('--json', action='store_true',
                        help='print the rows as JSON instead of a table')
    parser.add_argument('--ptxas', metavar='PRECISION',
                        type=Choice(['tf32', 'bf16', 'fp16']),
                        help='print ptxas\' report of each kernel\'s '
                        'training variant for sm_90a at this precision')
    parser.add_argument('--hidden', type=Choice([16, 32]), default=32,
                        help='with --ptxas: the band networks\' channels')
    return parser


def refuse_interpreter(parser: argparse.ArgumentParser) -> None:
    """A command line that compiles the kernels stops, naming the fix,
    where ``TRITON_INTERPRET`` is set (its kernels cannot be compiled)."""
    if os.environ.get('TRITON_INTERPRET', '0') not in ('', '0'):
        parser.error('unset TRITON_INTERPRET: the interpreter\'s kernels '
                     'cannot be compiled')


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    refuse_interpreter(parser)
    if args.ptxas:
        print(json.dumps({v.kernel: ptxas_report(v, 'sm_90')
                          for v in training_variants(args.ptxas,
                                                     args.hidden)}))
        return 0
    rows = compile_rows(args.archs, args.jobs)
    print(json.dumps(rows) if args.json else format_table(rows))
    return 0


if __name__ == '__main__':
    sys.exit(main())
