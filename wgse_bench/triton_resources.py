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
``HIDDEN_CHANNELS`` and each launch entry of the target, for sm_80 (A100),
sm_89 (L40, RTX 4090), sm_90 (H100, H200), sm_100 (B200) and sm_120 (RTX
5090, RTX PRO 6000). Band lengths are run-time values of the kernels, so
one compile serves every band.

The cost model (:func:`step_cost`) reads the compiled code: the
instructions of the loop over a band's coefficients (the step every
coefficient of a tile takes), all and tensor-core ones (``HMMA``,
``HGMMA``, sm_100's ``UTCHMMA``), as warp instructions per coefficient
position (times the
warps, over the pixels of a tile). An SM issues at most one warp
instruction per scheduler and clock, so :func:`predicted_ms` turns those
counts into a lower bound on a pass's time at a GPU's clock;
:func:`measured_against_predicted` sets that bound beside what a GPU
report's profile measured (``--against gpu.json``).

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

from wgse_mmseg.command_line import Choice, Integer, Number, Path
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

_POINTERS = ['w1_ptr', 'b1_ptr', 'w2_ptr', 'b2_ptr', 'w3_ptr', 'b3_ptr']
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
    from wgse_mmseg.core.wgse.triton_band_networks import (FORWARD_CONFIGS,
                                                           HIDDEN_CHANNELS,
                                                           TOLERANCES,
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


def predicted_ms(positions: float, instructions_per_position: float,
                 sms: int, clock_ghz: float, schedulers: int = 4) -> float:
    """The least time ``positions`` coefficient positions take at
    ``instructions_per_position`` warp instructions each, on ``sms`` SMs
    of ``schedulers`` issuing one warp instruction a clock each at
    ``clock_ghz``: every cycle issuing, none waiting."""
    return positions * instructions_per_position / (
        sms * schedulers * clock_ghz * 1e6)


def measured_against_predicted(report: Dict, rows: Sequence[Dict]
                               ) -> List[Dict]:
    """The band kernels a GPU report profiled, each beside the cost model's
    floor on the report's GPU. ``report``: the report's JSON (gpu.json, by
    :mod:`.gpu_report`; its ``profile`` section); ``rows``:
    :func:`compile_all`'s rows for the report's target. Per profiled
    precision and kernel: ``per_position`` (warp instructions a coefficient
    position), ``predicted_ms`` (:func:`predicted_ms` at the report's SMs
    and peak clock, times the kernel's launches), ``measured_ms`` and
    ``of_issue`` (predicted over measured: the share of the SMs' issue
    slots the kernel's instructions filled). The variants are the launch
    entries a training pass runs (no input gradient).

    Raises:
        ValueError: the report lacks what this needs (a GPU of one of
            :data:`ARCHITECTURES`, its SMs and clock, a profile), or
            ``rows`` holds no variant a profiled kernel ran.
    """
    env = report.get('environment') if isinstance(report, dict) else None
    if not isinstance(env, dict) or env.get('capability') not in \
            ARCHITECTURES or not env.get('sms') or \
            not env.get('sm_clock_mhz'):
        raise ValueError(
            f"the report names no GPU of {list(ARCHITECTURES)} with its SMs "
            f"and clock (environment's capability, sms, sm_clock_mhz; a "
            f"report from before they were recorded has no clock)")
    sections = report.get('sections')
    profile = sections.get('profile') if isinstance(sections, dict) else None
    measured = [r for r in profile.get('rows', []) if isinstance(r, dict)
                and r.get('status') == 'ok'] \
        if isinstance(profile, dict) else []
    if not measured:
        raise ValueError('the report has no profile of a WGSE pass (its '
                         "'profile' section did not run or failed)")
    try:
        return [row for run in measured
                for row in _against_floor(run, env, rows)]
    except (KeyError, TypeError) as err:
        raise ValueError(f"the report's profile is not as "
                         f'dev/gpu_report.py writes it ({err!r} missing or '
                         f'odd)') from err


def _against_floor(run: Dict, env: Dict, rows: Sequence[Dict]
                   ) -> List[Dict]:
    """:func:`measured_against_predicted`'s rows of one profiled pass."""
    from wgse_mmseg.core.wgse.triton_band_networks import (FORWARD_CONFIGS,
                                                           TOLERANCES,
                                                           backward_configs)
    if run['precision'] not in TOLERANCES:
        raise ValueError(f"the report's profile ran at precision "
                         f"{run['precision']!r}, not one of "
                         f'{list(TOLERANCES)}')
    entries = dict(band_forward=FORWARD_CONFIGS[0],
                   band_backward=backward_configs(False, run['precision'])[0])
    found = []
    for kernel_row in run.get('rows', []):
        kernel = next((k for k in entries if k in kernel_row['kernel']),
                      None)
        if kernel is None:
            continue
        entry = entries[kernel]
        compiled = [r for r in rows if r['arch'] == env['capability']
                    and r['kernel'] == kernel
                    and r['hidden'] == run['hidden']
                    and r['precision'] == run['precision']
                    and not r['input_grad']
                    and r['block'] == entry.block
                    and r['num_warps'] == entry.num_warps]
        if not compiled:
            raise ValueError(
                f"no compiled {kernel} for {env['capability']} at "
                f"{run['precision']}, {run['hidden']} channels, "
                f'{entry.name}')
        floor = kernel_row['launches'] * predicted_ms(
            run['positions'], compiled[0]['per_position'], env['sms'],
            env['sm_clock_mhz'] / 1e3)
        found.append(dict(
            precision=run['precision'], kernel=kernel,
            per_position=compiled[0]['per_position'],
            predicted_ms=floor, measured_ms=kernel_row['ms'],
            of_issue=floor / kernel_row['ms']))
    return found


def format_comparison(found: Sequence[Dict], report: Dict) -> str:
    """:func:`measured_against_predicted`'s rows as a Markdown table, the
    GPU named."""
    env = report['environment']
    lines = [f"{env.get('gpu', env['capability'])} ({env['capability']}, "
             f"{env['sms']} SMs at {env['sm_clock_mhz']:.0f} MHz, 4 "
             f'schedulers each):', '',
             '| precision | kernel | instr/position | issue floor ms '
             '| measured ms | of issue |',
             '|---|---|--:|--:|--:|--:|']
    lines += [f"| {r['precision']} | {r['kernel']} | "
              f"{r['per_position']:.1f} | {r['predicted_ms']:.2f} | "
              f"{r['measured_ms']:.2f} | {r['of_issue']:.0%} |"
              for r in found]
    return '\n'.join(lines)


def _cuobjdump() -> str:
    import triton
    path = os.path.join(os.path.dirname(triton.__file__), 'backends',
                        'nvidia', 'bin', 'cuobjdump')
    if not os.path.isfile(path):
        raise FileNotFoundError(f'{path}: the triton wheel ships no '
                                f'cuobjdump here')
    return path


def _compiled(variant: Variant, arch: str):
    """``(compiled kernel, its SASS text, cuobjdump's resource report)`` of
    ``variant`` for ``arch``. Needs triton with ``TRITON_INTERPRET``
    unset."""
    import triton
    from triton.backends.compiler import GPUTarget
    from triton.compiler import ASTSource

    from wgse_mmseg.core.wgse import triton_band_kernels as kernels
    from wgse_mmseg.core.wgse.triton_band_networks import (
        conv1_on_tensor_cores, taps_as_one_product)
    signature = dict(_SIGNATURES[variant.kernel])
    signature.update({name: '*fp32' for name in _POINTERS})
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
    signature.update({name: 'constexpr' for name in constants})
    source = ASTSource(fn=getattr(kernels, variant.kernel),
                       signature=signature, constexprs=constants)
    compiled = triton.compile(
        source, target=GPUTarget('cuda', ARCHITECTURES[arch][0], 32),
        options=dict(num_warps=variant.num_warps, maxnreg=variant.maxnreg))
    dump, sass = _disassembled(compiled)
    return compiled, sass, dump


def _disassembled(compiled) -> Tuple[str, str]:
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
    return _resources(variant, arch, *_compiled(variant, arch))


def _resources(variant: Variant, arch: str, compiled, sass: str,
               dump: str) -> Resources:
    """:class:`Resources` of a :func:`_compiled` kernel."""
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


def ptxas_reports(precision: str) -> Dict[str, str]:
    """:func:`ptxas_report` of each kernel's training variant at
    ``precision`` for sm_90, by kernel name. Runs in a fresh process with
    ``TRITON_INTERPRET`` unset."""
    return _run_fresh(['--ptxas', precision])


def ptxas_report(variant: Variant, arch: str) -> str:
    """What ``ptxas -v`` says of ``variant``'s PTX for ``arch`` (its
    notices, such as ``C7514``: ``wgmma`` products serialised, each waited
    for before the next; triton's own compile keeps none of it). Needs
    triton with ``TRITON_INTERPRET`` unset."""
    from triton import knobs
    compiled, _, _ = _compiled(variant, arch)
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


#: Coefficients of each band of WGSE's paper at T = 129 (db8, 5 levels):
#: approximation, then details from the coarsest
PAPER_BANDS = (18, 18, 22, 29, 43, 72)
#: The predictor's largest relative error on the one measurement of these
#: kernels' kind there is (the former kernels on an H200; docs/wgse_speed.md,
#: "A predictor"), with a point of margin: what a prediction of
#: :func:`predict_band_kernels` is stated with
PREDICTION_ERROR = 0.21


def makespan(durations: Sequence[float], slots: int) -> float:
    """When the last of programs of ``durations`` (in launch order) ends on
    ``slots`` resident places, each program taking the first place free:
    how a GPU's block scheduler fills its SMs."""
    import heapq
    places = [0.0] * max(1, min(slots, len(durations)))
    for duration in durations:
        heapq.heappush(places, heapq.heappop(places) + duration)
    return max(places)


def _program_cycles(variant: Variant, arch: str, pixels: int,
                    hardware: sass_timing.Hardware):
    """:func:`.sass_timing.program_cycles` of ``variant`` compiled for
    ``arch``, on band-major rows of ``pixels`` pixels, with the programs an
    SM holds."""
    compiled, sass, dump = _compiled(variant, arch)
    resources = _resources(variant, arch, compiled, sass, dump)
    layout = sass_timing.Layout(4, 4 * pixels, sass_timing.pixels_per_access(
        compiled.asm['ttgir'], variant.block))
    return sass_timing.program_cycles(sass, resources.programs_per_sm,
                                      variant.num_warps, layout, hardware)


def _training_variants(precision: str, hidden: int) -> List[Variant]:
    """The forward's and the backward's variants a training pass runs."""
    from wgse_mmseg.core.wgse.triton_band_networks import (FORWARD_CONFIGS,
                                                           backward_configs)
    return [Variant('band_forward', hidden, precision, False,
                    *FORWARD_CONFIGS[0]),
            Variant('band_backward', hidden, precision, False,
                    *backward_configs(False, precision)[0])]


def _predict_here(precision: str, batch: int, pixels: int,
                  lengths: Sequence[int], hidden: int,
                  hardware: sass_timing.Hardware) -> Dict:
    """:func:`predict_band_kernels`, compiled in this process."""
    from wgse_mmseg.core.wgse.triton_band_networks import work_division
    forward, backward = _training_variants(precision, hidden)
    found = dict(gpu=hardware.name, sms=hardware.sms,
                 clock_ghz=hardware.clock_ghz, precision=precision,
                 error=PREDICTION_ERROR)
    for variant, extra in ((forward, 2), (backward, 3)):
        cycles = _program_cycles(variant, 'sm_90', pixels, hardware)
        tiles = batch * -(-pixels // variant.block)
        if variant.kernel == 'band_forward':  # a program a tile and band
            durations = [cycles(length + extra) for length in lengths
                         for _ in range(tiles)]
        else:  # persistent: each program every step-th tile of its band
            durations = [
                cycles.fixed + cycles.per_step * (lengths[band] + extra) *
                len(range(first, tiles, step)) for band, first, step in
                work_division(lengths, tiles,
                              hardware.sms * cycles.programs)]
        found[variant.kernel] = makespan(
            durations, hardware.sms * cycles.programs) / (
                hardware.clock_ghz * 1e6)
        found[f'{variant.kernel}_per_step_cycles'] = cycles.per_step
        found[f'{variant.kernel}_programs_per_sm'] = cycles.programs
    return found


def predict_band_kernels(precision: str = 'tf32', batch: int = 4,
                         height: int = 256, width: int = 512,
                         hidden: int = 32, sms: int = 132,
                         clock_ghz: float = 1.98) -> Dict:
    """The band kernels' predicted times on a Hopper GPU (sm_90: H100,
    H200) for one WGSE training pass, compiled here (no GPU).

    Each kernel's training variant at ``precision`` (``'tf32'``, ``'bf16'``,
    ``'fp16'``) is compiled for sm_90, and its SASS run through
    :mod:`.sass_timing`'s model of one SM (ptxas' control bits, published
    latencies and rates, the programs an SM holds); the forward's programs
    (one a tile and band) and the backward's persistent ones
    (:func:`~wgse_mmseg.core.wgse.triton_band_networks.work_division`) are
    then placed on the GPU's ``sms`` SMs (:func:`makespan`). Runs in a
    fresh process with ``TRITON_INTERPRET`` unset.

    Args:
        precision: of the tensor-core products.
        batch, height, width: the spikes' ``B``, ``H``, ``W`` (the bands:
            :data:`PAPER_BANDS`, the paper's T = 129).
        hidden: the band networks' channels (16 or 32).
        sms, clock_ghz: the GPU's SMs and SM clock under load (default:
            the H200's).

    Returns:
        ``band_forward`` and ``band_backward``: predicted milliseconds of
        each kernel's launch (what ``torch.profiler`` reports per kernel);
        ``error``: the relative error to state them with
        (:data:`PREDICTION_ERROR`); the GPU's ``gpu``, ``sms``,
        ``clock_ghz``, the ``precision``, and per kernel its
        ``*_per_step_cycles`` (one SM, all its programs) and
        ``*_programs_per_sm``. The rest of a pass (the wavelet products,
        ``d3``, conv3's bias gradient) is not in it.

    Raises:
        ValueError: an argument out of range.
        RuntimeError: the kernels do not compile here.
    """
    from wgse_mmseg.core.wgse.triton_band_networks import (HIDDEN_CHANNELS,
                                                           TOLERANCES)
    if precision not in TOLERANCES or precision == 'ieee':
        raise ValueError(f'predict_band_kernels: precision must be one of '
                         f'the tensor-core ones {list(TOLERANCES)[1:]}, '
                         f'got {precision!r}')
    if hidden not in HIDDEN_CHANNELS:
        raise ValueError(f'predict_band_kernels: hidden must be one of '
                         f'{HIDDEN_CHANNELS}, got {hidden!r}')
    sizes = dict(batch=batch, height=height, width=width, sms=sms)
    bad = [k for k, v in sizes.items() if isinstance(v, bool) or
           not isinstance(v, int) or v < 1]
    if bad or isinstance(clock_ghz, bool) or not (
            isinstance(clock_ghz, (int, float)) and clock_ghz > 0):
        raise ValueError(f'predict_band_kernels: batch, height, width and '
                         f'sms must be positive integers and clock_ghz '
                         f'positive, got {sizes}, clock_ghz {clock_ghz!r}')
    return _run_fresh(['--predict', precision, '--shape', str(batch),
                       str(height), str(width), '--hidden', str(hidden),
                       '--sms', str(sms), '--clock-mhz',
                       str(clock_ghz * 1e3)])


#: the former kernels' arguments (pixel-major ``(N, C)`` coefficients, a
#: launch a band, its length a constant)
_FORMER_SIGNATURES = {
    'band_forward': dict(x_ptr='*fp32', y_ptr='*fp32', stride='i32',
                         offset='i32', pixels='i32'),
    'band_backward': dict(x_ptr='*fp32', gy_ptr='*fp32', gx_ptr='*fp32',
                          partial_ptr='*fp32', stride='i32', offset='i32',
                          pixels='i32'),
}
#: the launch entries the former kernels ran on an H200 (its autotuner's
#: choice at 4x256x512 pixels): ``(block, warps)``, and the steps a band's
#: program takes beyond its length
_FORMER_ENTRIES = dict(band_forward=(64, 4, 2), band_backward=(16, 4, 5))


def predict_former_kernels(source: str, batch: int = 4, height: int = 256,
                           width: int = 512) -> Dict[str, Dict[str, float]]:
    """The predictor applied to the kernels this repository's Triton
    backend ran before its band-major rewrite (``source``: their module's
    path: ``_triton_band_kernels.py`` of ``wgse_mmseg/core/wgse`` at commit
    3123fe6, ``git show``)
    at TF32 and 32 channels on an H200: per kernel, each band length of
    :data:`PAPER_BANDS` (as a string: JSON's keys) mapped to the predicted
    milliseconds of its launch (a launch a band, pixel-major coefficients
    of ``sum(PAPER_BANDS)`` columns), by the same model and hardware figures
    as :func:`predict_band_kernels`. Runs in a fresh process with
    ``TRITON_INTERPRET`` unset."""
    return _run_fresh(['--former', os.fspath(source), '--shape', str(batch),
                       str(height), str(width)])


def _predict_former_here(source: str, batch: int, pixels: int,
                         hidden: int, hardware: sass_timing.Hardware
                         ) -> Dict[str, Dict[int, float]]:
    """:func:`predict_former_kernels`, compiled in this process."""
    import importlib.util

    import triton
    from triton.backends.compiler import GPUTarget
    from triton.compiler import ASTSource
    spec = importlib.util.spec_from_file_location('former_kernels', source)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    columns = sum(PAPER_BANDS)
    found: Dict[str, Dict[int, float]] = {}
    for kernel, (block, warps, extra) in _FORMER_ENTRIES.items():
        for length in sorted(set(PAPER_BANDS)):
            signature = dict(_FORMER_SIGNATURES[kernel])
            signature.update({name: '*fp32' for name in _POINTERS})
            constants = dict(LENGTH=length, HIDDEN=hidden, BLOCK=block,
                             PRECISION='tf32')
            if kernel == 'band_backward':
                constants['INPUT_GRAD'] = False
            signature.update({name: 'constexpr' for name in constants})
            compiled = triton.compile(
                ASTSource(fn=getattr(module, kernel), signature=signature,
                          constexprs=constants),
                target=GPUTarget('cuda', 90, 32),
                options=dict(num_warps=warps))
            dump, sass = _disassembled(compiled)
            registers, shared = (int(x) for x in re.search(
                r'REG:(\d+) .*?SHARED:(\d+)', dump).groups())
            programs = programs_per_sm(
                registers, warps, shared + compiled.metadata.shared,
                'sm_90')
            layout = sass_timing.Layout(
                4 * columns, 4, sass_timing.pixels_per_access(
                    compiled.asm['ttgir'], block))
            cycles = sass_timing.program_cycles(sass, programs, warps,
                                                layout, hardware)
            tiles = batch * -(-pixels // block)
            found.setdefault(kernel, {})[length] = makespan(
                [cycles(length + extra)] * tiles, hardware.sms * programs
            ) / (hardware.clock_ghz * 1e6)
    return found


def _run_fresh(arguments: Sequence[str]):
    """This module's command line run in a fresh process with
    ``TRITON_INTERPRET`` unset, its JSON output read."""
    env = {k: v for k, v in os.environ.items() if k != 'TRITON_INTERPRET'}
    proc = subprocess.run([sys.executable, '-m', __name__, '--json',
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


def _compile_here(archs: Sequence[str], jobs: int) -> List[Dict]:
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
    return _run_fresh(['--jobs', str(jobs or os.cpu_count() or 1),
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
    parser.add_argument('--predict', metavar='PRECISION',
                        type=Choice(['tf32', 'bf16', 'fp16']),
                        help='print the band kernels\' predicted times on a '
                        'Hopper GPU at this precision (predict_band_kernels)')
    parser.add_argument('--ptxas', metavar='PRECISION',
                        type=Choice(['tf32', 'bf16', 'fp16']),
                        help='print ptxas\' report of each kernel\'s '
                        'training variant for sm_90a at this precision')
    parser.add_argument('--shape', nargs=3, metavar=('B', 'H', 'W'),
                        type=Integer(1, 1 << 16), default=[4, 256, 512],
                        help='with --predict or --former: the spikes\' '
                        'batch, height and width (default 4 256 512)')
    parser.add_argument('--hidden', type=Choice([16, 32]), default=32,
                        help='with --predict or --former: the band '
                        'networks\' channels')
    parser.add_argument('--sms', type=Integer(1, 1024), default=132,
                        help='with --predict: the GPU\'s SMs')
    parser.add_argument('--clock-mhz', type=Number(1, 10000,
                                                   strict_minimum=True),
                        default=1980.0,
                        help='with --predict: the GPU\'s SM clock under load')
    parser.add_argument('--former', metavar='SOURCE', type=Path('file'),
                        help='the former pixel-major kernels\' module '
                        '(git show 3123fe6:wgse_mmseg/core/wgse/'
                        '_triton_band_kernels.py): print the predictor\'s '
                        'times of their launches on an H200 at TF32')
    parser.add_argument('--against', metavar='REPORT', type=Path(),
                        help="a GPU report's gpu.json (dev/gpu_report.py): "
                        'compile for its GPU and print each profiled band '
                        "kernel's measured time beside the cost model's "
                        'floor, as the share of issue it reached')
    return parser


def _report_of_this_code(path: str) -> Dict:
    """The report at ``path``, checked to have measured the code here (its
    digest), so that what is compiled here is what ran there."""
    from .gpu_report import code_digest, read_report
    report = read_report(path)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    environment = report.get('environment')
    measured = environment.get('code') \
        if isinstance(environment, dict) else None
    here = code_digest(root)
    if measured != here:
        raise ValueError(f'{path}: it measured other code (digest '
                         f'{measured}) than this checkout\'s ({here}); '
                         f'compiling this code would not predict that run')
    return report


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if os.environ.get('TRITON_INTERPRET', '0') not in ('', '0'):
        parser.error('unset TRITON_INTERPRET: the interpreter\'s kernels '
                     'cannot be compiled')
    batch, height, width = args.shape
    if args.predict:
        hardware = sass_timing.H200._replace(
            sms=args.sms, clock_ghz=args.clock_mhz / 1e3)
        print(json.dumps(_predict_here(args.predict, batch, height * width,
                                       PAPER_BANDS, args.hidden, hardware)))
        return 0
    if args.ptxas:
        print(json.dumps({v.kernel: ptxas_report(v, 'sm_90')
                          for v in _training_variants(args.ptxas,
                                                      args.hidden)}))
        return 0
    if args.former:
        print(json.dumps(_predict_former_here(
            args.former, batch, height * width, args.hidden,
            sass_timing.H200)))
        return 0
    if args.against:
        try:
            report = _report_of_this_code(args.against)
            capability = report.get('environment', {}).get('capability')
            rows = _compile_here([capability], args.jobs) \
                if capability in ARCHITECTURES else []
            found = measured_against_predicted(report, rows)
        except ValueError as err:
            parser.error(f'--against {args.against}: {err}')
        print(json.dumps(found) if args.json else
              format_comparison(found, report))
        return 0
    rows = _compile_here(args.archs, args.jobs)
    print(json.dumps(rows) if args.json else format_table(rows))
    return 0


if __name__ == '__main__':
    sys.exit(main())
