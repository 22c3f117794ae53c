"""The timing model of compiled GPU code (``wgse_bench.sass_timing``): the
control bits it reads from SASS against hand-decoded encodings and against
the dependencies of real compiled code, and one SM's cycles on small
hand-written loops whose timing is worked out by hand."""
import re

import pytest

from wgse_bench import sass_timing as st

# the first instructions of a kernel as cuobjdump --dump-sass prints them
# (triton 3.6, sm_90a; its columns' spaces squeezed): each a line of text
# and its two encoding words
_SASS = '''
/*0000*/ LDC R1, c[0x0][0x28] ; /* 0x00000a00ff017b82 */
    /* 0x000e220000000800 */
/*0010*/ S2R R63, SR_CTAID.Y ; /* 0x00000000003f7919 */
    /* 0x000e6e0000002600 */
/*0020*/ LDC.64 R2, c[0x0][0x240] ; /* 0x00009000ff027b82 */
    /* 0x000e620000000a00 */
/*0050*/ LDC R15, c[0x0][0x230] ; /* 0x00008c00ff0f7b82 */
    /* 0x000ea20000000800 */
/*0060*/ S2R R54, SR_CTAID.X ; /* 0x0000000000367919 */
    /* 0x000ee20000002500 */
/*0080*/ S2R R65, SR_TID.X ; /* 0x0000000000417919 */
    /* 0x000f2a0000002100 */
/*00b0*/ IMAD.WIDE.U32 R2, R63, 0x4, R2 ; /* 0x000000043f027825 */
    /* 0x002fce00078e0002 */
/*00d0*/ LDG.E R9, desc[UR28][R2.64] ; /* 0x0000001c02097981 */
    /* 0x000922000c1e1900 */
/*00e0*/ IABS R11, R15 ; /* 0x0000000f000b7213 */
    /* 0x004fcc0000000000 */
/*0110*/ LOP3.LUT R8, R54, R15, RZ, 0x3c, !PT ; /* 0x0000000f36087212 */
    /* 0x008fe400078e3cff */
/*0120*/ LOP3.LUT R61, R65, 0x1f, RZ, 0xc0, !PT ; /* 0x000000... */
    /* 0x010fe400078ec0ff */
'''.replace('/* 0x000000... */', '/* 0x0000001f413d7812 */')


def test_control_bits_decode_as_worked_out_by_hand():
    code = st.parse_sass(_SASS)
    assert [i.address for i in code] == [
        0x0, 0x10, 0x20, 0x50, 0x60, 0x80, 0xb0, 0xd0, 0xe0, 0x110, 0x120]
    # 0x000922000c1e1900 >> 41 = 0x491 = 0b100_1001_0001: stall 1, yield
    # 1, write scoreboard 4, read scoreboard 4, wait mask 0
    load = code[7]
    assert load.opcode == 'LDG.E' and load.text.startswith('LDG.E R9')
    assert (load.stall, load.write_barrier, load.read_barrier,
            load.wait_mask) == (1, 4, 4, 0)
    # 0x008fe400078e3cff >> 41 = 0x47f2: stall 2, no scoreboards, waits
    # on scoreboard 3
    assert code[9][3:] == (2, None, None, 0b1000)


def test_every_result_is_waited_for_where_it_is_read():
    """ptxas' dependencies, read back: the first reader of a register an
    instruction writes through a scoreboard waits on that scoreboard (or
    an instruction between them does)."""
    code = st.parse_sass(_SASS)
    checked = 0
    for index, ins in enumerate(code):
        if ins.write_barrier is None:
            continue
        written = re.match(r'[\w.]+ (R\d+)', ins.text).group(1)
        for later, reader in enumerate(code[index + 1:], index + 1):
            if re.search(rf'\b{written}\b', reader.text.split(',', 1)[-1]
                         if ',' in reader.text else ''):
                assert any(c.wait_mask >> ins.write_barrier & 1
                           for c in code[index + 1:later + 1]), reader
                checked += 1
                break
    assert checked >= 4


def _ins(opcode, stall=1, wait=0, write=None, operands=''):
    return st.Instruction(0, opcode, f'{opcode} {operands}'.strip(), stall,
                          write, None, wait)


def _loop(*body):
    """``body`` then a backward branch, at consecutive addresses."""
    code = list(body) + [_ins('BRA', operands='0x0')]
    return [i._replace(address=16 * n) for n, i in enumerate(code)], \
        (0, len(body))


_ROWS = st.Layout(4, 4 << 20)


def _per_step(code, bounds, programs=1, warps=1, layout=_ROWS):
    short, long = (st.simulate(code, bounds, n, programs, warps, layout)
                   for n in (4, 12))
    return (long - short) / 8


def test_a_dependent_chain_takes_its_stall_counts():
    # two multiply-adds 4 cycles apart and the branch: 9 cycles a pass
    code, bounds = _loop(_ins('FFMA', 4), _ins('FFMA', 4))
    assert _per_step(code, bounds) == 9
    assert st.simulate(code, bounds, 3, 1, 1, _ROWS) == 27
    # two warps a scheduler (8 warps on 4), least recently issued first:
    # warp a at 0, 4, 8, b at 1, 5, 9; a waits a cycle for b's branch and
    # passes settle at 10 (a at 10, 14, 18, b at 11, 15, 19, a at 20)
    assert _per_step(code, bounds, warps=8) == 10


def test_issue_bound_with_two_warps_a_scheduler():
    code, bounds = _loop(_ins('FFMA'), _ins('FFMA'), _ins('FFMA'))
    assert _per_step(code, bounds) == 4
    assert _per_step(code, bounds, warps=8) == 8


def test_integer_pipe_takes_half_a_warp_a_cycle():
    code, bounds = _loop(_ins('IADD3'), _ins('IADD3'))
    assert _per_step(code, bounds) == 4  # 0, 2, branch at 3


def test_a_serialised_wgmma_waits_for_each_product():
    """Arrive, product, wait for it: 64x32x8 TF32 occupies the four tensor
    pipes 64*32*8 / (4 * 256) = 16 cycles; it finishes its shared-memory
    operand (29), those cycles and the tensor pipe's latency (24) after it
    starts: 69 after issue, then the wait and the branch issue."""
    hw = st.H200
    code, bounds = _loop(
        _ins('WARPGROUP.ARRIVE'), _ins('HGMMA.64x32x8.F32.TF32'),
        _ins('WARPGROUP.DEPBAR.LE', operands='gsb0, 0x0'))
    assert _per_step(code, bounds, warps=4) == \
        1 + hw.shared_latency + 16 + hw.tensor_latency + 2
    # one product allowed in flight: the wait of pass k waits for product
    # k - 1, so two passes take what one did
    code, bounds = _loop(
        _ins('WARPGROUP.ARRIVE'), _ins('HGMMA.64x32x8.F32.TF32'),
        _ins('WARPGROUP.DEPBAR.LE', operands='gsb0, 0x1'))
    assert _per_step(code, bounds, warps=4) == \
        (1 + hw.shared_latency + 16 + hw.tensor_latency + 2) / 2


def test_mma_sync_takes_its_share_of_the_tensor_pipe():
    # m16n8k8 TF32: 1024 multiply-adds at 256 * 2/3 a cycle: 6 cycles each
    code, bounds = _loop(_ins('HMMA.1688.F32.TF32'),
                         _ins('HMMA.1688.F32.TF32'))
    assert _per_step(code, bounds) == 12


def test_a_load_waits_on_device_memory_where_its_rows_are_new():
    hw = st.H200
    load = _ins('LDG.E', write=0, operands='R4, desc[UR4][R2.64]')
    use = _ins('FADD', wait=1, operands='R5, R4, R4')
    code, bounds = _loop(load, use)
    # band-major rows: a new sector every step; issue, one wavefront, the
    # latency, then the add and the branch
    assert _per_step(code, bounds) == 1 + hw.dram_latency + 2
    # pixel-major rows of 202 floats, 8 pixels a warp: lane p's sector
    # changes where (202 p + s) % 8 == 0, some lane's every even step; 8
    # lines a load
    former = st.Layout(4 * 202, 4, 8)
    assert [former.misses(s) for s in range(6)] == [True, False] * 3
    assert former.wavefronts(4) == 8
    assert _per_step(code, bounds, layout=former) == \
        (2 * (8 + 2) + hw.dram_latency + hw.l1_latency) / 2


def test_wavefronts_of_contiguous_rows():
    assert _ROWS.wavefronts(4) == 1 and _ROWS.wavefronts(16) == 4


def test_barrier_waits_for_the_last_warp():
    # warps 0-3 of one program; warp 4 of a second program shares
    # scheduler 0 with warp 0, which the barrier then holds up: every
    # warp of the first program waits for it
    code, bounds = _loop(_ins('FFMA'), _ins('BAR.SYNC.DEFER_BLOCKING',
                                            operands='0x0'))
    assert _per_step(code, bounds, warps=4) == 3
    assert _per_step(code, bounds, programs=2, warps=4) == 6


def test_loop_bounds_are_the_shortest_loop_that_loads():
    code, _ = _loop(_ins('LDG.E', write=0, operands='R4, [R2.64]'),
                    _ins('FADD', wait=1))
    assert st.loop_bounds(code) == (0, 2)
    with pytest.raises(ValueError, match='no loop'):
        st.loop_bounds([i._replace(opcode='LDS', text='LDS') if
                        i.opcode.startswith('LDG') else i for i in code])
    with pytest.raises(ValueError, match='no SASS'):
        st.parse_sass('LDG.E R4, [R2.64] ;')


def test_program_cycles_fit_a_line_through_two_lengths():
    code, bounds = _loop(_ins('LDG.E', write=0, operands='R4, [R2.64]'),
                         _ins('FADD', wait=1))

    def encoded(i):  # the control bits where parse_sass reads them
        write = 7 if i.write_barrier is None else i.write_barrier
        control = i.stall | write << 5 | 7 << 8 | i.wait_mask << 11
        return (f'/*{i.address:04x}*/ {i.text} ; /* 0x{0:016x} */\n'
                f'/* 0x{control << 41:016x} */')
    sass = '\n'.join(encoded(i) for i in code)
    assert st.parse_sass(sass) == code
    cycles = st.program_cycles(sass, 1, 1, _ROWS)
    assert cycles.per_step == 1 + st.H200.dram_latency + 2
    assert cycles(10) == cycles.fixed + 10 * cycles.per_step


_TTGIR = '''
#blocked = #ttg.blocked<{sizePerThread = [1, 1], threadsPerWarp = [1, 32], warpsPerCTA = [4, 1], order = [1, 0]}>
#blocked1 = #ttg.blocked<{sizePerThread = [1], threadsPerWarp = [32], warpsPerCTA = [4], order = [0]}>
#mma = #ttg.nvidia_mma<{versionMajor = 3, versionMinor = 0, warpsPerCTA = [4, 1], instrShape = [16, 32, 8]}>
    %4 = tt.load %3 : tensor<32x!tt.ptr<f32>, #ttg.slice<{dim = 0, parent = #blocked}>> loc(#loc1)
    %7 = tt.load %6, %5 : tensor<64x!tt.ptr<f32>, #ttg.slice<{dim = 1, parent = #blocked}>> loc(#loc2)
'''  # noqa: E501  (triton's lines, verbatim)


def test_pixels_a_warp_access_covers_by_layout():
    # a slice of [1, 32] lanes along its first dimension: one pixel
    assert st.pixels_per_access(_TTGIR, 64) == 1
    mma = _TTGIR + ('    %9 = tt.load %8 : tensor<64x!tt.ptr<f32>, '
                    '#ttg.slice<{dim = 1, parent = #mma}>> loc(#loc3)\n')
    assert st.pixels_per_access(mma, 64) == 8
    vector = _TTGIR + ('    %9 = tt.load %8 : tensor<64x!tt.ptr<f32>, '
                       '#blocked1> loc(#loc3)\n')
    assert st.pixels_per_access(vector, 64) == 32
    with pytest.raises(ValueError, match=r'\(128,\)'):
        st.pixels_per_access(_TTGIR, 128)
