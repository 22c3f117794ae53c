"""Everything about WGSE on a GPU, measured in one run: docs/gpu.md and
gpu.json beside it.

What ``dev/gpu_report.py`` runs (on a GPU machine that has torch and
triton but nothing of OpenMMLab: ``bash dev/gpu_report.sh``), the most
telling sections first, so that a run a time limit stops has measured what
decides the kernels' design; every figure is measured in the same run as
the baseline it is divided by:

* ``ceilings``: the device's clocks, copy bandwidth and bf16 matrix rate;
* ``band_kernels``: each Triton band kernel's launch at TF32 and bf16,
  beside the resources tool's prediction where it gives one;
* ``wgse``: WGSE forward+backward of the reference design and of every
  backend on the device at TF32 and bf16: time, peak memory, ratios;
* ``first_use``: the first-use check ``backend='auto'`` runs at each
  precision, and which backend it runs then;
* ``stalls``: one profiled launch of each band kernel with its warps' stall
  reasons (Nsight Compute; without it torch's profiler's times);
* ``tensor_cores``: ``tl.dot`` loops at the band kernels' tiles (``wgmma``
  and ``mma.sync`` on Hopper) against the bf16 matrix rate;
* ``profile``: one WGSE pass kernel by kernel (torch's profiler);
* ``correctness``: both backends against float64 at each precision;
* ``segmentation``, ``latency`` and ``paper``: PSPNet and SegFormer-B0
  training steps raw and with WGSE, batch-1 latency, the paper's shape;
* ``targets``: the figures against the targets the caller gives.

A measurement that fails is recorded with its error and the report goes
on; both files are rewritten after each section, and a resumed run
measures only the sections an earlier run of the same plan and code on the
same machine and software did not finish. A time budget leaves the
sections it has no room for to that resumed run. ``DRY_RUN`` runs every
section's code on the CPU at tiny shapes (Triton in its interpreter),
skipping what needs CUDA with the reason recorded.

Modules: :mod:`.measure` (correctness, the first-use check, segmentor
steps), :mod:`.kernels` (the band kernels and the pass, timed and
profiled), :mod:`.ceilings` (the device's ceilings, the tensor-core loops),
:mod:`.sections` (plans, order, budget, resume), :mod:`.targets` and
:mod:`.render` (docs/gpu.md and gpu.json).
"""
from .measure import check_correctness
from .render import read_report, write_report
from .sections import DRY_RUN, GPU, Plan, code_digest, run_report

__all__ = ['run_report', 'read_report', 'write_report']
