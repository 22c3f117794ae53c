"""What the Triton band kernels are built for, importable without torch or
Triton: the kernels (:mod:`wgse_mmseg.core.wgse.triton_band_networks`) and
the benchmarks' command lines (``wgse_bench``) read these one definitions,
so that ``--help`` and argument errors come at once."""
__all__ = []

#: Hidden widths the kernels take (``tl.dot`` needs powers of two >= 16).
#: Not 64: its TF32 backward needs more shared memory a program than sm_89
#: (L40, RTX 4090) gives one, and spills; the 'torch' backend runs it.
HIDDEN_CHANNELS = (16, 32)
#: Largest error against float64, relative to the largest magnitude of the
#: output or of each gradient, that the tests allow per precision of the
#: kernels' products (full float32 ``'ieee'``, TF32, fp16, bf16); TF32 keeps
#: fp16's 10 mantissa bits, bf16 7 (docs/wgse_speed.md has the errors
#: measured).
TOLERANCES = {'ieee': 1e-4, 'tf32': 3e-2, 'fp16': 3e-2, 'bf16': 2.5e-1}
