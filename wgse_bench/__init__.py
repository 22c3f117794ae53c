"""Every benchmark of the package, with one timer and one machine record.

* :mod:`.timing`: :func:`~.timing.time_calls` (wall and CPU seconds of
  repeated calls, CUDA synchronised) and :func:`~.timing.summarize`
  (median and MAD): the one timer;
* :mod:`.machine`: :func:`~.machine.machine_record` (device, CPU, load,
  versions): the one machine record; :func:`~.machine.run_isolated` runs
  a measurement in a fresh process;
* :mod:`.markdown`: the reports' Markdown tables;
* :mod:`.wgse`: WGSE forward+backward per backend against the reference
  design (``tools/analysis_tools/benchmark_wgse.py``);
* :mod:`.wgse_memory`: peak RSS growth per pixel and time of a WGSE
  training pass per CPU backend, beside another commit's work tree
  (``python -m wgse_bench.wgse_memory``);
* :mod:`.simulator`: the simulator's throughput and spike files' load time
  (``tools/analysis_tools/benchmark_simulator.py``);
* :mod:`.gpu_report`: everything about WGSE on a GPU in one run
  (``dev/gpu_report.py``, which holds the targets);
* :mod:`.triton_resources`: the Triton kernels compiled ahead of time for
  real GPUs, their registers, spills and occupancy (maintainers';
  ``python -m wgse_bench.triton_resources``);
* :mod:`.kernel_prediction`: what that compiled code predicts of a GPU's
  time, and the issue floor beside a GPU report's measurement
  (maintainers'; ``python -m wgse_bench.kernel_prediction``);
* :mod:`.segmentation`: what a spike segmentor costs: parameters, FLOPs,
  time, memory (``tools/analysis_tools/benchmark.py``, the experiment
  runner);
* :mod:`.reconstruction`: reconstruction methods scored on a REDS-layout
  folder (PSNR, SSIM) or on a real recording without ground truth (NIQE,
  BRISQUE, 2-D entropy) (``python -m wgse_bench.reconstruction``).

All but the last two need the core alone (torch, numpy), nothing of
OpenMMLab: they run on a GPU machine with torch alone. :mod:`.segmentation`
and :mod:`.reconstruction` measure the MMSeg layer's models and datasets,
so importing them imports it; :mod:`.gpu_report` imports
:mod:`.segmentation` only inside its segmentation jobs. Importing this
package imports none of its modules.
"""
