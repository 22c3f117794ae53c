"""A timing model of compiled GPU code: one SM issuing a kernel's SASS.

The resources tool's instruction count (:mod:`.triton_resources`, as time:
:func:`.kernel_prediction.predicted_ms`) is a floor: every scheduler
issuing every cycle. What it leaves out is in the compiled code too, and
this module reads it from there:

- **ptxas' own schedule.** Every SASS instruction of sm_70 and later carries
  control bits (the high word of its encoding): the cycles its warp must
  wait before issuing the next instruction (the stall count, which is how
  ptxas covers fixed latencies), the scoreboard a variable-latency result
  releases, and the scoreboards an instruction waits on. :func:`parse_sass`
  decodes them, so the dependencies the model honours are ptxas'.
- **Variable latencies** (:class:`Hardware`): shared memory, the L1, the
  L2 and device memory, the special-function unit and the tensor pipe,
  each a published figure, none taken from a measurement of these kernels.
- **Shared pipes.** The tensor pipe of each scheduler (``HMMA``; a warp
  group's ``HGMMA`` occupies all four), the integer/compare pipe (half a
  warp a cycle), and the SM's shared-memory and L1 data path (128 bytes a
  cycle), which every shared-memory access, shuffle and global access
  crosses in 128-byte wavefronts.
- **Serialised products and barriers.** ``WARPGROUP.DEPBAR`` waits for the
  warp group's products in flight (where ptxas serialises them, one after
  each); ``BAR.SYNC`` holds a program's warps until its last arrives.
- **Warps a scheduler.** :func:`simulate` runs every warp of the programs
  an SM holds (warp ``w`` of a program on scheduler ``w % 4``), each
  scheduler issuing one instruction a cycle from a ready warp, least
  recently issued first.
- **Where global loads come from** (:class:`Layout`): a step's load misses
  the L1 where its lanes reach a 32-byte sector they did not touch the step
  before (every step for band-major rows; pixel-major rows move 4 bytes a
  step), and then waits on device memory, which holds the coefficients
  (tensors several times the L2).

:func:`program_cycles` fits cycles ``= fixed + per_step * steps`` from two
simulated lengths of a program (its prologue, ``steps`` passes of the step
loop, its epilogue), so a band's edge steps (the loop runs ``L + 2`` or
``L + 3`` steps for ``L`` coefficients) and a program's set-up count.
Everything here is plain Python over the text of ``cuobjdump --dump-sass``:
no GPU.
"""
import re
from typing import Dict, List, NamedTuple, Sequence, Tuple

__all__ = []


class Instruction(NamedTuple):
    """One SASS instruction with its control bits: ``opcode`` (with its
    modifiers, ``'HMMA.1688.F32.TF32'``), the whole ``text``, ``stall``
    (cycles before the warp's next issue), ``write_barrier`` and
    ``read_barrier`` (the scoreboard it releases when its result is written
    or its operands read; ``None``: none), ``wait_mask`` (scoreboards it
    waits on, bit ``k`` for scoreboard ``k``)."""
    address: int
    opcode: str
    text: str
    stall: int
    write_barrier: object
    read_barrier: object
    wait_mask: int


class Hardware(NamedTuple):
    """What the model takes of a GPU, in its SM clock's cycles.

    Latencies: Accel-Sim's configuration of the H100 (SM90_H100,
    gpgpu-sim_distribution, from its microbenchmarks): L1 hit 41, shared
    memory 29, L2 237 beyond the L1, device memory 194 beyond the L2, the
    special-function unit 23, a tensor-core product 24. Rates: four
    schedulers an SM, each issuing one warp instruction a cycle, 32 FP32
    lanes and 16 integer lanes each (H100 whitepaper: 128 FP32 and 64 INT32
    units an SM), a shared-memory and L1 data path of 128 bytes a cycle, and
    dense tensor products of ``tensor_fma`` multiply-adds a cycle per
    scheduler by operand type (whitepaper: twice the A100's 1,024 FP16
    multiply-adds an SM a clock; TF32 half of that). ``mma.sync``
    (``HMMA``) reaches ``mma_sync_share`` of that rate on Hopper, where
    ``wgmma`` is needed for the peak (FlashAttention-3, Shah et al. 2024:
    about two thirds). ``clock_ghz`` and ``sms``: the GPU's."""
    name: str
    sms: int
    clock_ghz: float
    schedulers: int = 4
    l1_latency: int = 41
    shared_latency: int = 29
    l2_latency: int = 41 + 237
    dram_latency: int = 41 + 237 + 194
    sfu_latency: int = 23
    tensor_latency: int = 24
    wavefront_bytes: int = 128
    alu_cycles: int = 2
    tensor_fma: Tuple[Tuple[str, int], ...] = (
        ('TF32', 256), ('BF16', 512), ('F16', 512))
    mma_sync_share: float = 2 / 3


#: the H200 (SXM): 132 SMs; 1,980 MHz, the clock nvidia-smi read under load
#: on this workplace's H200 (KINDS.md) and the H100 SXM's boost clock
H200 = Hardware('NVIDIA H200', 132, 1.98)


class Layout(NamedTuple):
    """Where a kernel's step loads come from: ``pixel_bytes`` between the
    same coefficient of neighbouring pixels, ``step_bytes`` between a
    pixel's coefficients of neighbouring steps, and ``lanes``: the distinct
    neighbouring pixels one warp's access covers (:func:`pixels_per_access`:
    8 where a per-pixel vector is a slice of the tensor cores' result
    layout, whose four lanes of a quad share a row). Band-major ``(B, C,
    P)`` rows: 4 and ``4 P``; pixel-major ``(N, C)``: ``4 C`` and 4."""
    pixel_bytes: int
    step_bytes: int
    lanes: int = 32

    def misses(self, step: int) -> bool:
        """Whether a warp's load of step ``step`` touches a 32-byte sector
        its pixels did not touch the step before: then it waits on device
        memory, else on the L1."""
        return any((p * self.pixel_bytes + step * self.step_bytes) // 32 !=
                   (p * self.pixel_bytes + (step - 1) * self.step_bytes)
                   // 32 for p in range(self.lanes))

    def wavefronts(self, bytes_per_lane: int) -> int:
        """128-byte wavefronts of one warp's global access of
        ``bytes_per_lane`` each: one per line its pixels touch."""
        if self.pixel_bytes >= 128:
            return self.lanes
        return max(1, -(-32 * max(bytes_per_lane, self.pixel_bytes) // 128))


_LAYOUT = re.compile(r'^#(\w+) = #ttg\.(\w+)<(.*)>\s*$', re.M)


def pixels_per_access(ttgir: str, block: int) -> int:
    """The most distinct pixels one warp's global load of a ``(block,)``
    per-pixel vector covers in a kernel's triton GPU IR
    (``compiled.asm['ttgir']``), read from each load's layout: a slice of
    a tensor-core result layout (``nvidia_mma``) 8, a slice of a blocked
    layout its lanes along the pixels, a blocked vector its lanes."""
    layouts = {name: (kind, body) for name, kind, body in
               _LAYOUT.findall(ttgir)}
    found = []
    for match in re.finditer(
            rf'tt\.load [^\n]*: tensor<{block}x!tt\.ptr<\w+>, (#[^>\n]+>?>?)',
            ttgir):
        layout = match.group(1)
        slice_ = re.match(r'#ttg\.slice<\{dim = (\d), parent = #(\w+)\}>',
                          layout)
        kind, body = layouts.get(slice_.group(2) if slice_ else
                                 layout.lstrip('#').rstrip('>'), ('', ''))
        if kind == 'nvidia_mma':
            found.append(8)
        elif kind == 'blocked':
            lanes = [int(n) for n in re.search(
                r'threadsPerWarp = \[([\d, ]+)\]', body).group(1).split(',')]
            found.append(lanes[0] if slice_ and slice_.group(1) == '1' or
                         len(lanes) == 1 else lanes[-1])
    if not found:
        raise ValueError(f'no load of a ({block},) vector in the kernel\'s '
                         f'triton GPU IR')
    return max(found)


_CODE = re.compile(r'/\*([0-9a-f]{4,})\*/\s+(@!?U?P\w+\s+)?([A-Z][\w.]*)'
                   r'([^;]*);\s*/\* (0x[0-9a-f]{16}) \*/\s*\n\s*'
                   r'/\* (0x[0-9a-f]{16}) \*/')


def parse_sass(sass: str) -> List[Instruction]:
    """The instructions of ``cuobjdump --dump-sass`` text, in order, with
    the control bits of each (bits 105-125 of its 128-bit encoding: stall
    4 bits, yield 1, write and read scoreboard 3 each (7: none), wait mask
    6)."""
    found = []
    for address, _, opcode, operands, _, high in _CODE.findall(sass):
        control = (int(high, 16) >> 41) & 0x1FFFFF
        write, read = (control >> 5) & 7, (control >> 8) & 7
        found.append(Instruction(
            int(address, 16), opcode, f'{opcode}{operands}'.strip(),
            control & 15, None if write == 7 else write,
            None if read == 7 else read, (control >> 11) & 63))
    if not found:
        raise ValueError('no SASS instructions with their encodings in the '
                         'text (expected cuobjdump --dump-sass output)')
    return found


def loop_bounds(code: Sequence[Instruction]) -> Tuple[int, int]:
    """``(first, last)`` indices of the step loop in ``code``: the shortest
    range that a backward branch closes and that loads from global memory
    (the step over a band's coefficients, which loads the next ones; the
    backward kernel's loop over tiles encloses it, and on sm_100 the waits
    for the tensor cores' barriers are shorter loops that load nothing). A
    branch's target is its last operand, after a uniform predicate
    (``BRA.U UP0, 0x...``) where it has one, before the scheduling notes
    sm_120's code carries (``?trans6``)."""
    addresses = [i.address for i in code]
    loops = []
    for index, ins in enumerate(code):
        target = re.search(r'(0x[0-9a-f]+)\s*\)?\s*(?:[&?].*)?$', ins.text)
        if ins.opcode.startswith('BRA') and target and \
                int(target.group(1), 16) < ins.address:
            start = addresses.index(int(target.group(1), 16))
            if any(i.opcode.startswith('LDG') for i in code[start:index + 1]):
                loops.append((start, index))
    if not loops:
        raise ValueError('no loop that loads from global memory in the '
                         'compiled kernel')
    return min(loops, key=lambda bounds: bounds[1] - bounds[0])


_ALU = ('IADD3', 'LOP3', 'ISETP', 'SEL', 'FSEL', 'FMNMX', 'FSETP', 'PLOP3',
        'LEA', 'SHF', 'PRMT', 'IABS', 'VIADD', 'IMNMX', 'P2R', 'R2P', 'FLO',
        'POPC', 'BMSK', 'SGXT', 'LOP', 'ISCADD', 'F2FP')
_MIO = ('LDS', 'STS', 'LDSM', 'STSM', 'SHFL', 'ATOMS', 'LDG', 'STG', 'LD',
        'ST', 'RED', 'ATOMG', 'LDL', 'STL')


def _width(opcode: str) -> int:
    """Bytes a lane moves in a memory instruction (``.64``, ``.128``,
    ``.U8`` ... in its modifiers; 4 by default)."""
    for suffix, size in (('.128', 16), ('.64', 8), ('.U8', 1), ('.S8', 1),
                         ('.U16', 2), ('.S16', 2)):
        if suffix in opcode:
            return size
    return 4


def _matrix_fmas(opcode: str) -> Tuple[int, str]:
    """Multiply-adds and operand type of a tensor-core instruction:
    ``HGMMA.64x32x8.F32.TF32`` (M x N x K), ``HMMA.1688.F32.TF32``
    (m16n8k8), ``HMMA.16816.F32.BF16`` (m16n8k16)."""
    kind = next((t for t in ('TF32', 'BF16', 'F16') if
                 opcode.endswith('.' + t) or f'.{t}.' in opcode), 'F16')
    shape = re.search(r'\.(\d+)x(\d+)x(\d+)', opcode)
    if shape:
        m, n, k = map(int, shape.groups())
        return m * n * k, kind
    mma = re.search(r'HMMA\.168(\d+)', opcode)  # m16n8kK
    if mma is None:
        raise ValueError(f'{opcode}: a tensor-core shape not understood')
    return 16 * 8 * int(mma.group(1)), kind


class _Warp:
    """One warp's place in its trace (``pc``), the cycle it may issue
    again (``ready``), when each of its six scoreboards clears (``board``)
    and when it last issued (``last``)."""
    __slots__ = ('program', 'index', 'scheduler', 'pc', 'ready', 'board',
                 'last', 'done')

    def __init__(self, program, index, scheduler):
        self.program, self.index, self.scheduler = program, index, scheduler
        self.pc, self.ready, self.board = 0, 0, [0] * 6
        self.last, self.done = -1, False


def _trace(code, bounds, steps):
    """The instruction indices one warp runs: the prologue, ``steps``
    passes of the loop (its last instruction the backward branch), the
    epilogue; each with the pass it belongs to (-1 outside the loop)."""
    first, last = bounds
    trace = [(i, -1) for i in range(first)]
    for step in range(steps):
        trace += [(i, step) for i in range(first, last + 1)]
    trace += [(i, -1) for i in range(last + 1, len(code))
              if not (code[i].opcode.startswith('BRA') and
                      code[i].text.endswith(hex(code[i].address)))]
    return trace


def simulate(code: Sequence[Instruction], bounds: Tuple[int, int],
             steps: int, programs: int, warps: int, layout: Layout,
             hardware: Hardware = H200) -> int:
    """Cycles one SM takes to run ``programs`` programs of ``warps`` warps
    each through ``code`` (the kernel's SASS, :func:`parse_sass`), the step
    loop at ``bounds`` (:func:`loop_bounds`) taken ``steps`` times,
    all programs starting together. Every instruction of the prologue and
    epilogue runs once (branches there are not followed) and every
    instruction of the loop each pass, predicated or not. Global loads of
    the loop wait on device memory or the L1 as ``layout`` says, those
    outside it on the L2 (the parameters all programs read)."""
    hw = hardware
    rates = dict(hw.tensor_fma)
    trace = _trace(code, bounds, steps)
    sched_warps: List[List[_Warp]] = [[] for _ in range(hw.schedulers)]
    all_warps = []
    for program in range(programs):
        for index in range(warps):
            warp = _Warp(program, index,
                         (program * warps + index) % hw.schedulers)
            sched_warps[warp.scheduler].append(warp)
            all_warps.append(warp)
    tensor_free = [0] * hw.schedulers
    alu_free = [0] * hw.schedulers
    mio_free = 0
    barrier: Dict[tuple, List[_Warp]] = {}
    # per (program, warp group): finish cycles of its products, in order,
    # and per warp the products it has issued
    group_products: Dict[tuple, List[int]] = {}
    group_pending: Dict[tuple, List[int]] = {}
    issued_products: Dict[_Warp, int] = {w: 0 for w in all_warps}
    blocked: Dict[_Warp, object] = {}
    cycle = 0
    remaining = len(all_warps)
    while remaining:
        progressed = False
        next_event = None
        for s in range(hw.schedulers):
            best = None
            for warp in sched_warps[s]:
                if warp.done or warp in blocked:
                    continue
                index, step = trace[warp.pc]
                ins = code[index]
                start = warp.ready
                if ins.wait_mask:
                    start = max([start] + [warp.board[k] for k in range(6)
                                           if ins.wait_mask >> k & 1])
                base = ins.opcode.split('.')[0]
                if base == 'HMMA':
                    start = max(start, tensor_free[s])
                elif base in _ALU:
                    start = max(start, alu_free[s])
                if ins.opcode.startswith('WARPGROUP.DEPBAR'):
                    key = (warp.program, warp.index // 4)
                    allowed = int(ins.text.rsplit(',', 1)[1], 16)
                    finishes = group_products.get(key, [])
                    mine = issued_products[warp]
                    if mine > len(finishes):  # its products not yet started
                        start = None
                    elif mine > allowed:  # all but `allowed` finished
                        start = max(start, sorted(finishes[:mine])[
                            mine - allowed - 1])
                if start is None:
                    continue
                if start <= cycle:
                    if best is None or warp.last < best.last:
                        best = warp
                elif next_event is None or start < next_event:
                    next_event = start
            if best is None:
                continue
            progressed = True
            warp = best
            index, step = trace[warp.pc]
            ins = code[index]
            base = ins.opcode.split('.')[0]
            warp.last = cycle
            warp.ready = cycle + max(ins.stall, 1)
            done_at = None  # when its result is written
            read_at = cycle + 1  # when its operands are read
            if base in _MIO:
                if base in ('LDG', 'STG', 'LD', 'ST', 'RED', 'ATOMG'):
                    fronts = layout.wavefronts(_width(ins.opcode)) \
                        if step >= 0 else 1
                    latency = (hw.dram_latency if layout.misses(step)
                               else hw.l1_latency) if step >= 0 \
                        else hw.l2_latency
                elif base in ('LDSM', 'STSM'):
                    count = re.search(r'\.(\d)$', ins.opcode)
                    fronts = int(count.group(1)) if count else 1
                    latency = hw.shared_latency
                elif base in ('LDL', 'STL'):
                    fronts, latency = 1, hw.l1_latency
                else:
                    fronts = max(1, 32 * _width(ins.opcode) //
                                 hw.wavefront_bytes)
                    latency = hw.shared_latency
                begin = max(cycle, mio_free)
                mio_free = begin + fronts
                read_at = begin + fronts
                done_at = begin + fronts + latency
            elif base == 'HMMA':
                fmas, kind = _matrix_fmas(ins.opcode)
                occupancy = fmas / (rates[kind] * hw.mma_sync_share)
                tensor_free[s] = cycle + occupancy
                done_at = cycle + occupancy + hw.tensor_latency
            elif base == 'HGMMA':
                key = (warp.program, warp.index // 4)
                issued_products[warp] += 1
                pending = group_pending.setdefault(key, [])
                number = issued_products[warp]
                if len(pending) < number:
                    pending.append(0)
                pending[number - 1] += 1
                if pending[number - 1] == min(4, warps):
                    fmas, kind = _matrix_fmas(ins.opcode)
                    occupancy = fmas / (4 * rates[kind])
                    first = key[1] * 4
                    pipes = [(first + k) % hw.schedulers
                             for k in range(min(4, warps))]
                    begin = max([cycle] + [tensor_free[p] for p in pipes])
                    for p in pipes:
                        tensor_free[p] = begin + occupancy
                    group_products.setdefault(key, []).append(
                        begin + hw.shared_latency + occupancy +
                        hw.tensor_latency)
            elif base in _ALU:
                alu_free[s] = cycle + hw.alu_cycles
            elif ins.write_barrier is not None:
                done_at = cycle + hw.sfu_latency
            if ins.write_barrier is not None and done_at is not None:
                board = ins.write_barrier
                warp.board[board] = max(warp.board[board], done_at)
            if ins.read_barrier is not None:
                board = ins.read_barrier
                warp.board[board] = max(warp.board[board], read_at)
            warp.pc += 1
            if base == 'BAR' and '.SYNC' in ins.opcode:
                key = (warp.program, warp.pc)
                arrived = barrier.setdefault(key, [])
                arrived.append(warp)
                if len(arrived) == warps:
                    for other in arrived:
                        blocked.pop(other, None)
                        other.ready = max(other.ready, cycle + 1)
                    del barrier[key]
                else:
                    blocked[warp] = key
            if warp.pc == len(trace):
                warp.done = True
                remaining -= 1
        if remaining and not progressed:
            if next_event is None:
                raise RuntimeError('the timing model deadlocked (a warp '
                                   'waits on nothing that can come)')
            cycle = max(cycle + 1, int(next_event))
        else:
            cycle += 1
    return cycle


class ProgramCycles(NamedTuple):
    """A program's cycles on one SM holding ``programs`` of them at once:
    ``fixed + per_step * steps``."""
    fixed: float
    per_step: float
    programs: int

    def __call__(self, steps: float) -> float:
        return self.fixed + self.per_step * steps


def program_cycles(sass: str, programs: int, warps: int, layout: Layout,
                   hardware: Hardware = H200,
                   lengths: Tuple[int, int] = (16, 32)) -> ProgramCycles:
    """:class:`ProgramCycles` of a kernel's SASS text, fitted through two
    :func:`simulate` runs of ``lengths`` steps (the step loop's cost is the
    same every pass but the first few, which the fit's slope leaves out)."""
    code = parse_sass(sass)
    bounds = loop_bounds(code)
    short, long = (simulate(code, bounds, n, programs, warps, layout,
                            hardware) for n in lengths)
    per_step = (long - short) / (lengths[1] - lengths[0])
    return ProgramCycles(short - per_step * lengths[0], per_step, programs)
