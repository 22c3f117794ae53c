"""Triton kernels of WGSE's band network, forward and backward.

The network of one band (the paper's, ``num_blocks=1``), per pixel, over
its ``L`` coefficients ``x``, all convolutions 'same' padded with zeros
(kernel 3, ``H`` hidden channels)::

    h1 = relu(conv1(x))           # 1 -> H
    h2 = relu(conv2(h1) + x)      # H -> H, the input broadcast over channels
    y  = relu(conv3(h2))          # H -> 1

Layout: coefficients are band-major, ``(B, C, P)`` (``P`` pixels, the
bands' ``C`` coefficients stacked), so coefficient ``t`` of a tile of
``BLOCK`` pixels is one contiguous row: every load and store of a step
reads or writes ``BLOCK`` neighbouring floats. One launch runs every band:
the band's length and first row come from two small tensors, its
parameters from the bands' stacked parameters.

A program streams along its band: step ``s`` loads ``x[s + 1]``, computes
``h1[s]`` and passes it on at once: its products with conv2's three taps
complete ``h2[s - 1]`` and go into the partial sums of ``h2[s]`` and
``h2[s + 1]``; ``h2[s - 1]`` through conv3's taps likewise completes
``y[s - 2]``. So a step hands one ``h1`` tile to the tensor cores (not a
window of three), two ``(BLOCK, H)`` partial sums are all the registers
carry between steps, and nothing but ``y`` and where it is positive (one
byte a coefficient) is written. The ``H x H`` layer is
``tl.dot`` products over the ``BLOCK`` pixels of a tile (tensor cores:
TF32, or fp16/bf16 operands with float32 accumulation, as ``PRECISION``
says); the rest is element-wise.

The backward pass starts from ``d3``, the gradient at the last
convolution's pre-activation: ``y``'s gradient where the forward's mask
says ``y > 0``, else zero (one element-wise pass, by the caller). Then
``band_backward``, persistent: a fixed number of programs, each given one
band and every ``step``-th tile of it (``work``: band, first tile, step),
streams each tile, recomputing ``h1`` and ``h2`` and running the gradient
one or two steps behind (at step ``s``: ``d2`` up to ``s - 1``, ``d1`` up
to ``s - 2``, the input gradient up to ``s - 3``), and keeps its band's
parameter-gradient sums in registers across its tiles: one row of a
``(programs, P_band)`` buffer per program (a few MB), written once. The
caller adds the rows of each band (no atomics: the same bits every run).
It carries four ``(BLOCK, H)`` tiles between steps (the last two ``h1``,
two partial sums of their gradient) and loads the rest each step, which
is what lets it run 32-pixel tiles without spilling: its window of ``x``
(loaded whole), and ``d3``, one float a coefficient (forming ``d3`` from
``y``'s gradient and the mask in the kernel cost 6-14 more warp
instructions a position and spilled).

Parameters are float32, each kind stacked over the bands, contiguous:
``conv1`` ``(bands, H, 1, 3)``, ``conv2`` ``(bands, H, H, 3)``, ``conv3``
``(bands, 1, H, 3)``, biases ``(bands, H)``, ``(bands, H)``, ``(bands, 1)``.
"""
import triton
import triton.language as tl


@triton.jit
def _dot(a, b, PRECISION: tl.constexpr):
    """``a @ b`` with float32 accumulation; ``PRECISION``: ``'ieee'``,
    ``'tf32'``, ``'fp16'`` or ``'bf16'`` (the operands' rounding)."""
    if PRECISION == 'fp16':
        return tl.dot(a.to(tl.float16), b.to(tl.float16))
    elif PRECISION == 'bf16':
        return tl.dot(a.to(tl.bfloat16), b.to(tl.bfloat16))
    else:
        return tl.dot(a, b, input_precision=PRECISION)


@triton.jit
def _grad_dot(a, b, PRECISION: tl.constexpr):
    """A product with a gradient operand: as :func:`_dot`, but bf16 where
    the products are fp16. Under AMP's fp16 the loss is scaled (up to 2^16
    by ``GradScaler``) so that small gradients survive; fp16 operands of
    the scaled gradients would overflow (65504) where the float32
    convolutions they replace do not, bf16 has float32's range."""
    if PRECISION == 'fp16':
        return tl.dot(a.to(tl.bfloat16), b.to(tl.bfloat16))
    else:
        return _dot(a, b, PRECISION)


@triton.jit
def _taps(ptr, HIDDEN: tl.constexpr):
    """The three taps of a 1-channel side's ``(H, 1, 3)`` or ``(1, H, 3)``
    weight, each ``(1, H)``."""
    channels = tl.arange(0, HIDDEN)
    return (tl.load(ptr + channels * 3)[None, :],
            tl.load(ptr + channels * 3 + 1)[None, :],
            tl.load(ptr + channels * 3 + 2)[None, :])


@triton.jit
def _wide_offsets(HIDDEN: tl.constexpr):
    """``(H_in, H_out)`` offsets of tap 0 in an ``(H_out, H_in, 3)``
    weight: element ``[i, o]`` is ``o * 3H + i * 3``."""
    channels = tl.arange(0, HIDDEN)
    return channels[:, None] * 3 + channels[None, :] * (HIDDEN * 3)


@triton.jit
def _transposed_wide_offsets(HIDDEN: tl.constexpr):
    """``(H_out, H_in)`` offsets of tap 0 in an ``(H_out, H_in, 3)``
    weight: element ``[o, i]`` is ``o * 3H + i * 3``."""
    channels = tl.arange(0, HIDDEN)
    return channels[:, None] * (HIDDEN * 3) + channels[None, :] * 3


@triton.jit
def _two_taps(ptr, HIDDEN: tl.constexpr):
    """``(H_in, 2 H_out)``: taps 0 and 1 of the ``(H_out, H_in, 3)`` weight
    at ``ptr`` side by side (tap 0 in columns ``0`` to ``H``): one product
    with it is both taps' products."""
    i = tl.arange(0, HIDDEN)[:, None]
    column = tl.arange(0, 2 * HIDDEN)[None, :]
    return tl.load(ptr + (column % HIDDEN) * (3 * HIDDEN) + i * 3 +
                   column // HIDDEN)


@triton.jit
def _halves(product, BLOCK: tl.constexpr, HIDDEN: tl.constexpr):
    """The two ``(BLOCK, H)`` column halves of ``product`` ``(BLOCK, 2
    H)``, the first first."""
    return tl.split(tl.permute(tl.reshape(product, (BLOCK, 2, HIDDEN)),
                               (0, 2, 1)))


@triton.jit
def _band_weights(band, w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr, b3_ptr,
                  HIDDEN: tl.constexpr):
    """Band ``band``'s weights as a step uses them: conv1's taps ``(1, H)``
    and bias, conv2's taps ``(H_in, H_out)`` and bias, conv3's taps
    ``(1, H)`` and its scalar bias."""
    channels = tl.arange(0, HIDDEN)
    w1_0, w1_1, w1_2 = _taps(w1_ptr + band * (3 * HIDDEN), HIDDEN)
    w2 = w2_ptr + band * (3 * HIDDEN * HIDDEN) + _wide_offsets(HIDDEN)
    w3_0, w3_1, w3_2 = _taps(w3_ptr + band * (3 * HIDDEN), HIDDEN)
    return (w1_0, w1_1, w1_2,
            tl.load(b1_ptr + band * HIDDEN + channels)[None, :],
            tl.load(w2), tl.load(w2 + 1), tl.load(w2 + 2),
            tl.load(b2_ptr + band * HIDDEN + channels)[None, :],
            w3_0, w3_1, w3_2, tl.load(b3_ptr + band))


@triton.jit
def _tile_rows(tile, band, pixels, columns, tiles_per_sample, offsets_ptr,
               BLOCK: tl.constexpr):
    """Where tile ``tile`` of band ``band`` lies: the element offset of its
    first row (coefficient 0 of the band, first pixel of the tile; int64)
    and the tile's pixel columns ``(BLOCK,)`` with their mask."""
    sample = tile // tiles_per_sample
    cols = (tile % tiles_per_sample) * BLOCK + tl.arange(0, BLOCK)
    first = (sample * columns + tl.load(offsets_ptr + band)).to(
        tl.int64) * pixels
    return first, cols, cols < pixels


@triton.jit
def _bias_at(t, length, bias):
    """A layer's bias ``(1, H)`` at coefficient ``t``: ``bias`` inside the
    band, ``-inf`` outside it, so that the ReLU after the layer gives zero
    there. The choice is made once on the bias, not per element of the
    ``(BLOCK, H)`` tile (a select fewer per element; the pre-activation
    is finite wherever the inputs are)."""
    return tl.where((t >= 0) & (t < length), bias, float('-inf'))


@triton.jit
def _h1(t, x_p, x_c, x_n, w1_0, w1_1, w1_2, b1, length):
    """``h1[t]`` ``(BLOCK, H)`` from ``x[t - 1]``, ``x[t]``, ``x[t + 1]``;
    zero outside the band."""
    return tl.maximum(_bias_at(t, length, b1) + w1_0 * x_p[:, None] +
                      w1_1 * x_c[:, None] + w1_2 * x_n[:, None], 0.0)


@triton.jit
def _conv1_taps(r, shift, w1_0, w1_1, w1_2):
    """``(16, H)``: conv1's taps ``(1, H)`` in rows ``shift`` to ``shift +
    2``, the rest zero (``r``: the row numbers ``(16, 1)``). The product of
    :func:`_load_window` with it is conv1 at coefficient ``s + shift - 2``."""
    return tl.where(r == shift, w1_0, tl.where(
        r == shift + 1, w1_1, tl.where(r == shift + 2, w1_2, 0.0)))


@triton.jit
def _step_window(c, x_p, x_c, x_n):
    """``(BLOCK, 16)``: columns 0-2 the ``(BLOCK,)`` window ``x[s - 1]``,
    ``x[s]``, ``x[s + 1]``, the rest zero (``c``: the column numbers
    ``(1, 16)``). Its product with :func:`_conv1_taps` at shift 0 is conv1
    at ``s``."""
    return tl.where(c == 0, x_p[:, None], tl.where(
        c == 1, x_c[:, None], tl.where(c == 2, x_n[:, None], 0.0)))


@triton.jit
def _load_window(x_ptr, first, row, cols, valid, s, length, c):
    """``(BLOCK, 16)``: columns 0-4 the tile's coefficients ``x[s - 3]`` to
    ``x[s + 1]`` (zero outside the band), column 5 ones, the rest zero
    (``c``: the column numbers ``(1, 16)``). One masked load: the columns a
    thread holds past 4 are known at compile time, so they load nothing."""
    t = s - 3 + c
    xs = tl.load(x_ptr + first + t.to(tl.int64) * row + cols[:, None],
                 mask=valid[:, None] & (c < 5) & (t >= 0) & (t < length),
                 other=0.0)
    return tl.where(c == 5, 1.0, xs)


@triton.jit
def _h1_of_window(t, xs, taps, b1, length, PRECISION: tl.constexpr):
    """``h1[t]`` ``(BLOCK, H)``, :func:`_h1` on tensor cores: the product of
    the window ``xs`` (:func:`_load_window`) with conv1's ``taps`` at ``t``'s
    rows (:func:`_conv1_taps`); zero outside the band."""
    return tl.maximum(_bias_at(t, length, b1) + _dot(xs, taps, PRECISION),
                      0.0)


@triton.jit
def band_forward(x_ptr, out_ptr, mask_ptr, pixels, columns, tiles_per_sample,
                 lengths_ptr, offsets_ptr,
                 w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr, b3_ptr,
                 HIDDEN: tl.constexpr, BLOCK: tl.constexpr,
                 PRECISION: tl.constexpr, CONV1_DOT: tl.constexpr,
                 TAPS_01_AS_ONE: tl.constexpr):
    """The network on ``x`` ``(B, C, P)``: program ``(tile, band)`` runs
    band ``band`` on the ``BLOCK`` pixels of tile ``tile`` (tiles numbered
    sample by sample, ``tiles_per_sample`` each). Writes ``y`` into
    ``out`` and where ``y > 0`` (1, else 0) into ``mask`` (uint8; both
    ``(B, C, P)``): the backward pass's gradient at the last convolution's
    pre-activation is ``y``'s gradient there and zero elsewhere.
    ``CONV1_DOT``: conv1 as a product on tensor cores
    (:func:`_step_window`, the operands rounded as ``PRECISION`` says),
    else float32 multiply-adds (:func:`_h1`). ``TAPS_01_AS_ONE``: conv2's
    taps 0 and 1 as one product (:func:`_two_taps`), whose results only
    element-wise sums read; where each tap is its own product, the results
    carried to the next step as the next products' accumulators make
    ptxas wait for each of sm_90's ``wgmma`` before issuing the next.
    Elsewhere the wider product costs registers (it spills on sm_80, sm_89,
    sm_100 and sm_120, and in full float32) and there is nothing to
    gain."""
    tile = tl.program_id(0)
    band = tl.program_id(1)
    length = tl.load(lengths_ptr + band)
    first, cols, valid = _tile_rows(tile, band, pixels, columns,
                                    tiles_per_sample, offsets_ptr, BLOCK)
    row = pixels.to(tl.int64)
    (w1_0, w1_1, w1_2, b1, w2_0, w2_1, w2_2, b2, w3_0, w3_1, w3_2,
     b3) = _band_weights(band, w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr,
                         b3_ptr, HIDDEN)

    # Each value starts as its own tensor: triton carries a variable into
    # the next iteration only if the loop body changes its value, so two
    # names starting as one tensor (p_1 = p_0 = zeros) would leave p_1 = p_0
    # looking unchanged and the loop computing with its first value.
    if CONV1_DOT:
        # conv1's taps at rows 0-2 of a (16, H) matrix: a product with the
        # window x[s - 1], x[s], x[s + 1] (columns 0-2) is conv1 at s
        c = tl.arange(0, 16)[None, :]
        taps = _conv1_taps(tl.arange(0, 16)[:, None], 0, w1_0, w1_1, w1_2)
    if TAPS_01_AS_ONE:
        w2_01 = _two_taps(w2_ptr + band * (3 * HIDDEN * HIDDEN), HIDDEN)
    x_1 = tl.zeros((BLOCK, ), tl.float32)  # x[s - 1]
    x_0 = tl.load(x_ptr + first + cols, mask=valid, other=0.0)  # x[s]
    # x[s + 1], loaded a step before the step that reads it, so that the
    # load from device memory overlaps a whole step's products
    x_n = tl.load(x_ptr + first + row + cols, mask=valid & (1 < length),
                  other=0.0)
    # conv2's pre-activation of h2[s - 1] and h2[s] without the taps of the
    # h1 values still to come (h2[-1] lies outside the band: -inf)
    p_1 = tl.full((BLOCK, HIDDEN), float('-inf'), tl.float32)
    p_0 = b2 + x_0[:, None]
    # conv3's of y[s - 1] and y[s], likewise
    q_1 = tl.zeros((BLOCK, ), tl.float32)
    q_0 = tl.zeros((BLOCK, ), tl.float32)
    for s in range(0, length + 2):
        x_nn = tl.load(x_ptr + first + (s + 2) * row + cols,
                       mask=valid & (s + 2 < length), other=0.0)
        # h1[s] through conv2's three taps: the last one h2[s - 1] needed
        if CONV1_DOT:
            h1_0 = _h1_of_window(s, _step_window(c, x_1, x_0, x_n), taps,
                                 b1, length, PRECISION)
        else:
            h1_0 = _h1(s, x_1, x_0, x_n, w1_0, w1_1, w1_2, b1, length)
        h2_1 = tl.maximum(p_1 + _dot(h1_0, w2_2, PRECISION), 0.0)
        if TAPS_01_AS_ONE:
            t_0, t_1 = _halves(_dot(h1_0, w2_01, PRECISION), BLOCK, HIDDEN)
            p_1 = p_0 + t_1
            p_0 = _bias_at(s + 1, length, b2) + x_n[:, None] + t_0
        else:
            p_1 = p_0 + _dot(h1_0, w2_1, PRECISION)
            p_0 = (_bias_at(s + 1, length, b2) + x_n[:, None] +
                   _dot(h1_0, w2_0, PRECISION))
        # h2[s - 1] through conv3's: y[s - 2] before its ReLU
        a3 = q_1 + tl.sum(h2_1 * w3_2, axis=1)
        q_1 = q_0 + tl.sum(h2_1 * w3_1, axis=1)
        q_0 = b3 + tl.sum(h2_1 * w3_0, axis=1)
        at = first + (s - 2) * row + cols
        tl.store(out_ptr + at, tl.maximum(a3, 0.0), mask=valid & (s >= 2))
        tl.store(mask_ptr + at, (a3 > 0).to(tl.uint8), mask=valid & (s >= 2))
        x_1, x_0, x_n = x_0, x_n, x_nn


@triton.jit
def band_backward(x_ptr, d3_ptr, gx_ptr, partial_ptr, work_ptr, pixels,
                  columns, tiles_per_sample, tiles, lengths_ptr, offsets_ptr,
                  w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr, b3_ptr,
                  HIDDEN: tl.constexpr, BLOCK: tl.constexpr,
                  PRECISION: tl.constexpr, INPUT_GRAD: tl.constexpr):
    """Gradients of ``sum(y * gy)`` from ``d3`` (``gy`` where
    ``band_forward``'s mask is set, else 0; ``x``, ``d3``, ``gx``: ``(B, C,
    P)``): the input's into ``gx`` (when ``INPUT_GRAD``), and this program's
    parameter sums into row ``program_id`` of ``partial_ptr``, laid out as
    ``[dW1 (H, 1, 3), db1, dW2 (H, H, 3), db2, dW3 (1, H, 3)]`` of its
    band (conv3's bias gradient is the sum of ``d3``, which the caller
    takes). ``work_ptr`` ``(programs, 3)`` int32: per program its band, its
    first tile and the step between its tiles (of ``tiles`` in all).

    Step ``s`` recomputes ``h1[s]`` and, with the two ``h1`` of the steps
    before, ``h2[s - 1]``; ``d2[s - 1]`` follows from three values of
    ``d3``; the ``H x H`` layer's transposed products scatter ``d2[s - 1]``
    into its three neighbours' partial sums (``e_*``), completing
    ``d1[s - 2]``, so the ``(BLOCK, H)`` tiles carried between steps are
    two ``h1`` and two partial sums. conv1 runs on tensor cores: the step's
    window of ``x`` is one ``(BLOCK, 16)`` tile loaded whole
    (:func:`_load_window`), and ``h1[s]`` its product with conv1's taps
    placed at the rows of ``x[s - 1 .. s + 1]`` (:func:`_conv1_taps`),
    which leaves it in the layout of the products it feeds; the transposed
    window times ``d1`` sums conv1's weight and bias gradients over the
    pixels.
    conv3's weight gradient is summed element-wise in float32, in three
    ``(BLOCK, H)`` sums over the program's steps reduced over the pixels at
    the end: three multiply-adds a value, fewer instructions than a product
    on tensor cores, which would need ``h2`` split into two parts of the
    operands' precision (``h2`` carries more significant bits than bf16 or
    TF32 hold); so is conv2's bias gradient, the sum of ``d2``."""
    pid = tl.program_id(0)
    band = tl.load(work_ptr + pid * 3)
    length = tl.load(lengths_ptr + band)
    row = pixels.to(tl.int64)
    (w1_0, w1_1, w1_2, b1, w2_0, w2_1, w2_2, b2, w3_0, w3_1, w3_2,
     b3) = _band_weights(band, w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr,
                         b3_ptr, HIDDEN)
    w2t_0 = tl.trans(w2_0)
    w2t_1 = tl.trans(w2_1)
    w2t_2 = tl.trans(w2_2)
    r = tl.arange(0, 16)[:, None]
    # h1[s] is _load_window(...) @ taps (the window's x[s - 1 .. s + 1])
    taps = _conv1_taps(r, 2, w1_0, w1_1, w1_2)
    c = tl.arange(0, 16)[None, :]

    # sums over this program's tiles: conv2's weight transposed, (H_out,
    # H_in) per tap; a (16, H) tile whose rows 0-2 are conv1's taps and row
    # 5 its bias (g_1); conv3's taps and conv2's bias, one (BLOCK, H) sum
    # each (g_3_k, g_b2), reduced over the pixels at the end (a reduction
    # across the warps each step cost more: 1-12% of the step)
    g_w2t_0 = tl.zeros((HIDDEN, HIDDEN), tl.float32)
    g_w2t_1 = tl.zeros((HIDDEN, HIDDEN), tl.float32)
    g_w2t_2 = tl.zeros((HIDDEN, HIDDEN), tl.float32)
    g_1 = tl.zeros((16, HIDDEN), tl.float32)
    g_3_0 = tl.zeros((BLOCK, HIDDEN), tl.float32)
    g_3_1 = tl.zeros((BLOCK, HIDDEN), tl.float32)
    g_3_2 = tl.zeros((BLOCK, HIDDEN), tl.float32)
    g_b2 = tl.zeros((BLOCK, HIDDEN), tl.float32)
    for tile in range(tl.load(work_ptr + pid * 3 + 1), tiles,
                      tl.load(work_ptr + pid * 3 + 2)):
        first, cols, valid = _tile_rows(tile, band, pixels, columns,
                                        tiles_per_sample, offsets_ptr, BLOCK)
        # names: d3_k is d3[s - k], h1_k h1[s - k], each its own tensor
        # (see band_forward); 'part of' sums still miss the taps of later
        # steps
        d3_2 = tl.zeros((BLOCK, ), tl.float32)
        d3_1 = tl.zeros((BLOCK, ), tl.float32)
        e_1 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # part of dh1[s - 1]
        h1_1 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # outside the band
        h1_2 = tl.zeros((BLOCK, HIDDEN), tl.float32)
        e_2 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # part of dh1[s - 2]
        gx_3 = tl.zeros((BLOCK, ), tl.float32)  # part of gx[s - 3]
        gx_2 = tl.zeros((BLOCK, ), tl.float32)  # part of gx[s - 2]
        for s in range(0, length + 3):
            # the window x[s - 3 .. s + 1] loaded whole each step (its rows
            # are in the L1 cache from the steps before): carried from step
            # to step as five vectors instead, they cost register moves and
            # a select per column, 9-12% more warp instructions a position.
            # x[s - 1] is loaded again for the residual, in the layout of the
            # (BLOCK, H) tiles: taking it from the window's column costs
            # more (a reduction across the warps holding the columns)
            xs = _load_window(x_ptr, first, row, cols, valid, s, length, c)
            x_1 = tl.load(x_ptr + first + (s - 1) * row + cols,
                          mask=valid & (s >= 1) & (s - 1 < length), other=0.0)
            d3_0 = tl.load(d3_ptr + first + s * row + cols,
                           mask=valid & (s < length), other=0.0)
            # forward: h1[s] (h1[s - 1], h1[s - 2] from the steps before),
            # h2[s - 1]
            h1_0 = _h1_of_window(s, xs, taps, b1, length, PRECISION)
            h2_1 = (_bias_at(s - 1, length, b2) +
                    _dot(h1_2, w2_0, PRECISION) +
                    _dot(h1_1, w2_1, PRECISION) +
                    _dot(h1_0, w2_2, PRECISION) + x_1[:, None])
            h2_1 = tl.maximum(h2_1, 0.0)
            # dW3[k] += h2[u]^T d3[u + 1 - k], u = s - 1
            g_3_0 += h2_1 * d3_0[:, None]
            g_3_1 += h2_1 * d3_1[:, None]
            g_3_2 += h2_1 * d3_2[:, None]
            # d2[s - 1]
            d2 = tl.where(h2_1 > 0, d3_0[:, None] * w3_0 +
                          d3_1[:, None] * w3_1 + d3_2[:, None] * w3_2, 0.0)
            g_b2 += d2
            # dW2[:, :, k]^T += d2[u]^T h1[u - 1 + k]
            d2t = tl.trans(d2)
            g_w2t_0 += _grad_dot(d2t, h1_2, PRECISION)
            g_w2t_1 += _grad_dot(d2t, h1_1, PRECISION)
            g_w2t_2 += _grad_dot(d2t, h1_0, PRECISION)
            # d1[s - 2]: d2[u] reaches dh1[u - 1 + k] through tap k
            d1 = tl.where(h1_2 > 0, e_2 + _grad_dot(d2, w2t_0, PRECISION),
                          0.0)
            e_2 = e_1 + _grad_dot(d2, w2t_1, PRECISION)
            e_1 = _grad_dot(d2, w2t_2, PRECISION)
            # dW1[k] += x[v - 1 + k] d1[v], v = s - 2 (window columns 0-2);
            # db1 (column 5). TF32 operands under fp16 and bf16 too: d1 is
            # a sum of 3H products and carries more bits than bf16 holds (10
            # on the first-use check's exact problem, whose bf16 check it
            # would fail), under fp16 a scaled gradient (see _grad_dot), and
            # x carries fp16's bits, which bf16 would cut; TF32 keeps them
            g_1 += _dot(tl.trans(xs), d1,
                        'tf32' if PRECISION != 'ieee' else PRECISION)
            if INPUT_GRAD:
                # gx[s - 3]: x[t] reaches h1[t + 1 - k] through conv1's
                # tap k and h2[t] through the residual
                gx = gx_3 + tl.sum(d1 * w1_0, axis=1)
                tl.store(gx_ptr + first + (s - 3) * row + cols, gx,
                         mask=valid & (s >= 3))
                gx_3 = gx_2 + tl.sum(d1 * w1_1, axis=1)
                gx_2 = tl.sum(d1 * w1_2 + d2, axis=1)
            d3_2, d3_1 = d3_1, d3_0
            h1_2, h1_1 = h1_1, h1_0

    channels = tl.arange(0, HIDDEN)
    part = partial_ptr + pid.to(tl.int64) * (8 * HIDDEN +
                                             3 * HIDDEN * HIDDEN)
    for k in tl.static_range(3):
        tl.store(part + channels * 3 + k, tl.sum(tl.where(r == k, g_1, 0.0),
                                                 axis=0))
    part += 3 * HIDDEN
    tl.store(part + channels, tl.sum(tl.where(r == 5, g_1, 0.0), axis=0))
    part += HIDDEN
    wide = _transposed_wide_offsets(HIDDEN)
    tl.store(part + wide, g_w2t_0)
    tl.store(part + wide + 1, g_w2t_1)
    tl.store(part + wide + 2, g_w2t_2)
    part += 3 * HIDDEN * HIDDEN
    tl.store(part + channels, tl.sum(g_b2, axis=0))
    part += HIDDEN
    tl.store(part + channels * 3, tl.sum(g_3_0, axis=0))
    tl.store(part + channels * 3 + 1, tl.sum(g_3_1, axis=0))
    tl.store(part + channels * 3 + 2, tl.sum(g_3_2, axis=0))
