"""Triton kernels of WGSE's band network, forward and backward.

The network of one band (the paper's, ``num_blocks=1``), per pixel, over
its ``L`` coefficients ``x``, all convolutions 'same' padded with zeros
(kernel 3, ``H`` hidden channels)::

    h1 = relu(conv1(x))           # 1 -> H
    h2 = relu(conv2(h1) + x)      # H -> H, the input broadcast over channels
    y  = relu(conv3(h2))          # H -> 1

A program takes ``BLOCK`` pixels (rows of the ``(N, C)`` coefficients) of
one band and streams along the band: iteration ``s`` loads ``x[s + 1]``
and computes ``h1[s]``, ``h2[s - 1]`` and ``y[s - 2]`` from the last three
values of the layer below, so only a sliding window of three ``(BLOCK, H)``
tiles per layer lives in registers and nothing but ``y`` is written. The
``H x H`` layer is three ``tl.dot`` products per step (tensor cores:
TF32, or fp16/bf16 operands with float32 accumulation, as ``PRECISION``
says); the rest is element-wise.

The backward kernel streams the same way, recomputing the forward window
and running the gradient a few steps behind it: at iteration ``s`` it has
``d3`` (the gradient at ``y``'s pre-activation) up to ``s - 2``, ``d2`` up
to ``s - 3``, ``d1`` up to ``s - 4`` and the input gradient up to
``s - 5``. Each program writes its parameter-gradient sums, in the
parameters' own layouts, to its row of a ``(programs, P)`` buffer; the
caller adds the rows (no atomics: the same bits every run).

Weights are read once per program: ``conv1`` ``(H, 1, 3)``, ``conv2``
``(H, H, 3)``, ``conv3`` ``(1, H, 3)``, contiguous, float32.
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
def _wide_taps(ptr, HIDDEN: tl.constexpr):
    """The three taps of the ``(H_out, H_in, 3)`` weight, each as the
    ``(H_in, H_out)`` matrix that multiplies a ``(BLOCK, H_in)`` tile."""
    offsets = _wide_offsets(HIDDEN)
    return (tl.load(ptr + offsets), tl.load(ptr + offsets + 1),
            tl.load(ptr + offsets + 2))


@triton.jit
def _load_weights(w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr, b3_ptr,
                  HIDDEN: tl.constexpr):
    """One band's weights as the step uses them: conv1's taps ``(1, H)``
    and bias, conv2's taps ``(H_in, H_out)`` and bias, conv3's taps
    ``(1, H)`` and its scalar bias."""
    channels = tl.arange(0, HIDDEN)
    w1_0, w1_1, w1_2 = _taps(w1_ptr, HIDDEN)
    w2_0, w2_1, w2_2 = _wide_taps(w2_ptr, HIDDEN)
    w3_0, w3_1, w3_2 = _taps(w3_ptr, HIDDEN)
    return (w1_0, w1_1, w1_2, tl.load(b1_ptr + channels)[None, :],
            w2_0, w2_1, w2_2, tl.load(b2_ptr + channels)[None, :],
            w3_0, w3_1, w3_2, tl.load(b3_ptr))


@triton.jit
def _h1(t, x_p, x_c, x_n, w1_0, w1_1, w1_2, b1, LENGTH: tl.constexpr):
    """``h1[t]`` ``(BLOCK, H)`` from ``x[t - 1]``, ``x[t]``, ``x[t + 1]``;
    zero outside the band."""
    h1 = tl.maximum(b1 + w1_0 * x_p[:, None] + w1_1 * x_c[:, None] +
                    w1_2 * x_n[:, None], 0.0)
    return tl.where((t >= 0) & (t < LENGTH), h1, 0.0)


@triton.jit
def _hidden_step(s, x_1, x_0, x_n, h1_2, h1_1, w1_0, w1_1, w1_2, b1, w2_0,
                 w2_1, w2_2, b2, LENGTH: tl.constexpr,
                 PRECISION: tl.constexpr):
    """``h1[s]`` and ``h2[s - 1]``, each ``(BLOCK, H)`` and zero outside
    the band, from ``x[s - 1]``, ``x[s]``, ``x[s + 1]`` and ``h1[s - 2]``,
    ``h1[s - 1]``."""
    h1_0 = _h1(s, x_1, x_0, x_n, w1_0, w1_1, w1_2, b1, LENGTH)
    h2_1 = (b2 + _dot(h1_2, w2_0, PRECISION) + _dot(h1_1, w2_1, PRECISION) +
            _dot(h1_0, w2_2, PRECISION) + x_1[:, None])
    h2_1 = tl.where((s >= 1) & (s <= LENGTH), tl.maximum(h2_1, 0.0), 0.0)
    return h1_0, h2_1


@triton.jit
def band_forward(x_ptr, y_ptr, stride, offset, pixels,
                 w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr, b3_ptr,
                 LENGTH: tl.constexpr, HIDDEN: tl.constexpr,
                 BLOCK: tl.constexpr, PRECISION: tl.constexpr):
    """``y[:, offset:offset + L]`` from ``x[:, offset:offset + L]``, both
    ``(pixels, stride)`` row-major."""
    rows = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    valid = rows < pixels
    x_row = x_ptr + rows.to(tl.int64) * stride + offset
    y_row = y_ptr + rows.to(tl.int64) * stride + offset
    (w1_0, w1_1, w1_2, b1, w2_0, w2_1, w2_2, b2, w3_0, w3_1, w3_2,
     b3) = _load_weights(w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr, b3_ptr,
                         HIDDEN)

    # Each window value starts as its own tensor: triton carries a variable
    # into the next iteration only if the loop body changes its value, so
    # two names starting as one tensor (h1_2 = h1_1 = zeros) would leave
    # h1_2 = h1_1 looking unchanged and h1[s - 2] zero in every step.
    x_1 = tl.zeros((BLOCK, ), tl.float32)  # x[s - 1]
    x_0 = tl.load(x_row, mask=valid, other=0.0)  # x[s]
    h1_2 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # h1[s - 2]
    h1_1 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # h1[s - 1]
    h2_3 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # h2[s - 3]
    h2_2 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # h2[s - 2]
    for s in range(0, LENGTH + 2):
        x_n = tl.load(x_row + s + 1, mask=valid & (s + 1 < LENGTH),
                      other=0.0)
        h1_0, h2_1 = _hidden_step(s, x_1, x_0, x_n, h1_2, h1_1, w1_0, w1_1,
                                  w1_2, b1, w2_0, w2_1, w2_2, b2, LENGTH,
                                  PRECISION)
        y = tl.maximum(
            b3 + tl.sum(h2_3 * w3_0 + h2_2 * w3_1 + h2_1 * w3_2, axis=1),
            0.0)
        tl.store(y_row + s - 2, y, mask=valid & (s >= 2))
        x_1, x_0 = x_0, x_n
        h1_2, h1_1 = h1_1, h1_0
        h2_3, h2_2 = h2_2, h2_1


@triton.jit
def band_backward(x_ptr, gy_ptr, gx_ptr, partial_ptr, stride, offset,
                  pixels, w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr, b3_ptr,
                  LENGTH: tl.constexpr, HIDDEN: tl.constexpr,
                  BLOCK: tl.constexpr, PRECISION: tl.constexpr,
                  INPUT_GRAD: tl.constexpr):
    """Gradients of ``sum(y * gy)``: the input's into ``gx`` (when
    ``INPUT_GRAD``; same layout as ``x``), and this program's parameter
    sums into row ``program_id`` of ``partial_ptr``, laid out as
    ``[dW1 (H, 1, 3), db1, dW2 (H, H, 3), db2, dW3 (1, H, 3), db3]``.

    Registers are what limits this kernel, so it carries as few
    ``(BLOCK, H)`` tiles between steps as it can: ``h1`` is recomputed
    from the window of ``x`` wherever it is needed (three multiply-adds a
    value), and each ``tl.dot`` of the two ``H x H`` layers scatters one
    new tile into its three neighbours' partial sums (``a2_*`` for ``h2``'s
    pre-activation, ``e1_*`` for ``d1``), so that tile is converted to a
    ``tl.dot`` operand once per step instead of once per tap."""
    pid = tl.program_id(0)
    rows = pid * BLOCK + tl.arange(0, BLOCK)
    valid = rows < pixels
    x_row = x_ptr + rows.to(tl.int64) * stride + offset
    gy_row = gy_ptr + rows.to(tl.int64) * stride + offset
    gx_row = gx_ptr + rows.to(tl.int64) * stride + offset
    (w1_0, w1_1, w1_2, b1, w2_0, w2_1, w2_2, b2, w3_0, w3_1, w3_2,
     b3) = _load_weights(w1_ptr, b1_ptr, w2_ptr, b2_ptr, w3_ptr, b3_ptr,
                         HIDDEN)
    w2t_0 = tl.trans(w2_0)
    w2t_1 = tl.trans(w2_1)
    w2t_2 = tl.trans(w2_2)

    # windows (names: x_k is x[s - k]), each its own tensor (see
    # band_forward); 'part of' sums still miss the taps of later steps
    x_5 = tl.zeros((BLOCK, ), tl.float32)
    x_4 = tl.zeros((BLOCK, ), tl.float32)
    x_3 = tl.zeros((BLOCK, ), tl.float32)
    x_2 = tl.zeros((BLOCK, ), tl.float32)
    x_1 = tl.zeros((BLOCK, ), tl.float32)
    x_0 = tl.load(x_row, mask=valid, other=0.0)
    a2_1 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # part of a2[s - 1]
    a2_0 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # part of a2[s]
    h2_3 = tl.zeros((BLOCK, HIDDEN), tl.float32)
    h2_2 = tl.zeros((BLOCK, HIDDEN), tl.float32)
    d3_4 = tl.zeros((BLOCK, ), tl.float32)
    d3_3 = tl.zeros((BLOCK, ), tl.float32)
    e1_4 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # part of d1[s - 4]
    e1_3 = tl.zeros((BLOCK, HIDDEN), tl.float32)  # part of d1[s - 3]
    gx_5 = tl.zeros((BLOCK, ), tl.float32)  # part of gx[s - 5]
    gx_4 = tl.zeros((BLOCK, ), tl.float32)  # part of gx[s - 4]
    # parameter-gradient sums; conv2's transposed, (H_out, H_in) per tap
    g_w1_0 = tl.zeros((HIDDEN, ), tl.float32)
    g_w1_1 = tl.zeros((HIDDEN, ), tl.float32)
    g_w1_2 = tl.zeros((HIDDEN, ), tl.float32)
    g_b1 = tl.zeros((HIDDEN, ), tl.float32)
    g_w2t_0 = tl.zeros((HIDDEN, HIDDEN), tl.float32)
    g_w2t_1 = tl.zeros((HIDDEN, HIDDEN), tl.float32)
    g_w2t_2 = tl.zeros((HIDDEN, HIDDEN), tl.float32)
    g_b2 = tl.zeros((HIDDEN, ), tl.float32)
    g_w3_0 = tl.zeros((HIDDEN, ), tl.float32)
    g_w3_1 = tl.zeros((HIDDEN, ), tl.float32)
    g_w3_2 = tl.zeros((HIDDEN, ), tl.float32)
    g_b3 = tl.zeros((BLOCK, ), tl.float32)
    for s in range(0, LENGTH + 5):
        x_n = tl.load(x_row + s + 1, mask=valid & (s + 1 < LENGTH),
                      other=0.0)
        # forward: h1[s], h2[s - 1], y[s - 2]
        h1_0 = _h1(s, x_1, x_0, x_n, w1_0, w1_1, w1_2, b1, LENGTH)
        h2_1 = _dot(h1_0, w2_2, PRECISION) + a2_1 + b2 + x_1[:, None]
        h2_1 = tl.where((s >= 1) & (s <= LENGTH), tl.maximum(h2_1, 0.0), 0.0)
        a2_1 = a2_0 + _dot(h1_0, w2_1, PRECISION)
        a2_0 = _dot(h1_0, w2_0, PRECISION)
        y = b3 + tl.sum(h2_3 * w3_0 + h2_2 * w3_1 + h2_1 * w3_2, axis=1)
        gy = tl.load(gy_row + s - 2,
                     mask=valid & (s >= 2) & (s - 2 < LENGTH), other=0.0)
        # d3[s - 2]: gy is zero outside the band and the rows
        d3_2 = tl.where(y > 0, gy, 0.0)
        g_w3_0 += tl.sum(h2_3 * d3_2[:, None], axis=0)
        g_w3_1 += tl.sum(h2_2 * d3_2[:, None], axis=0)
        g_w3_2 += tl.sum(h2_1 * d3_2[:, None], axis=0)
        g_b3 += d3_2
        # d2[s - 3] (h2 is zero outside the band, so is d2 there)
        d2_3 = d3_2[:, None] * w3_0 + d3_3[:, None] * w3_1 + \
            d3_4[:, None] * w3_2
        d2_3 = tl.where(h2_3 > 0, d2_3, 0.0)
        # dW2[:, :, k]^T += d2[t]^T h1[t - 1 + k], t = s - 3
        d2t_3 = tl.trans(d2_3)
        h1_4 = _h1(s - 4, x_5, x_4, x_3, w1_0, w1_1, w1_2, b1, LENGTH)
        h1_3 = _h1(s - 3, x_4, x_3, x_2, w1_0, w1_1, w1_2, b1, LENGTH)
        h1_2 = _h1(s - 2, x_3, x_2, x_1, w1_0, w1_1, w1_2, b1, LENGTH)
        g_w2t_0 += _dot(d2t_3, h1_4, PRECISION)
        g_w2t_1 += _dot(d2t_3, h1_3, PRECISION)
        g_w2t_2 += _dot(d2t_3, h1_2, PRECISION)
        g_b2 += tl.sum(d2_3, axis=0)
        # d1[s - 4]; d2[s - 3] reaches d1[s - 4 + k] through tap k
        d1_4 = tl.where(h1_4 > 0, e1_4 + _dot(d2_3, w2t_0, PRECISION), 0.0)
        e1_4 = e1_3 + _dot(d2_3, w2t_1, PRECISION)
        e1_3 = _dot(d2_3, w2t_2, PRECISION)
        g_w1_0 += tl.sum(x_5[:, None] * d1_4, axis=0)
        g_w1_1 += tl.sum(x_4[:, None] * d1_4, axis=0)
        g_w1_2 += tl.sum(x_3[:, None] * d1_4, axis=0)
        g_b1 += tl.sum(d1_4, axis=0)
        if INPUT_GRAD:
            # gx[s - 5]: x[t] reaches h1[t + 1 - k] through conv1's tap k
            # and h2[t] through the residual
            gx = gx_5 + tl.sum(d1_4 * w1_0, axis=1)
            tl.store(gx_row + s - 5, gx, mask=valid & (s >= 5))
            gx_5 = gx_4 + tl.sum(d1_4 * w1_1, axis=1)
            gx_4 = tl.sum(d1_4 * w1_2 + d2_3, axis=1)
        x_5, x_4, x_3, x_2, x_1, x_0 = x_4, x_3, x_2, x_1, x_0, x_n
        h2_3, h2_2 = h2_2, h2_1
        d3_4, d3_3 = d3_3, d3_2

    channels = tl.arange(0, HIDDEN)
    part = partial_ptr + pid.to(tl.int64) * (8 * HIDDEN +
                                             3 * HIDDEN * HIDDEN + 1)
    tl.store(part + channels * 3, g_w1_0)
    tl.store(part + channels * 3 + 1, g_w1_1)
    tl.store(part + channels * 3 + 2, g_w1_2)
    part += 3 * HIDDEN
    tl.store(part + channels, g_b1)
    part += HIDDEN
    wide = _transposed_wide_offsets(HIDDEN)
    tl.store(part + wide, g_w2t_0)
    tl.store(part + wide + 1, g_w2t_1)
    tl.store(part + wide + 2, g_w2t_2)
    part += 3 * HIDDEN * HIDDEN
    tl.store(part + channels, g_b2)
    part += HIDDEN
    tl.store(part + channels * 3, g_w3_0)
    tl.store(part + channels * 3 + 1, g_w3_1)
    tl.store(part + channels * 3 + 2, g_w3_2)
    part += 3 * HIDDEN
    tl.store(part, tl.sum(g_b3, axis=0))
