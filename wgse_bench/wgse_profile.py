"""Where one WGSE forward+backward pass spends its time on a GPU.

:func:`profile_pass` runs one pass (after a warm-up that compiles the
kernels) under ``torch.profiler`` and keeps the device's kernels as intervals;
:func:`summarize` turns them into each kernel's share of the pass and the
gaps between kernels (the span from the first kernel's start to the last
one's end that no kernel covers), so that every millisecond of the pass is
either a named kernel or a gap, and into the Triton band kernels' achieved
TFLOP/s against the device's peak (:data:`PEAK_TFLOPS`).

The band kernels' arithmetic (:func:`band_kernel_flops`) counts the
``H x H`` products, the work of the tensor cores: per coefficient position
``2 * 3 * H * H`` FLOPs for each of the layer's products, three in the
backward kernel (the recomputed forward, the weight gradient and the
gradient of ``h1``), one in the forward kernel.
"""
from typing import Dict, List, NamedTuple, Optional, Sequence

import torch

__all__ = []

#: Dense tensor-core peak in TFLOP/s (without sparsity; float32
#: accumulation) of data-centre GPUs, by a part of the name the driver
#: reports and precision, the first entry whose key the name contains
#: applying: a board's variants before the name they share ('NVIDIA H100
#: PCIe' is not an 'H100' SXM board). The vendor's datasheets give these
#: figures with sparsity, twice the dense ones; TF32 runs at half the 16-bit
#: rate on all of them. GeForce boards halve the 16-bit rate with float32
#: accumulation and are not listed: no fraction of peak is printed there.
PEAK_TFLOPS = (
    ('H100 NVL', dict(tf32=417.5, bf16=835.0, fp16=835.0)),
    ('H100 PCIe', dict(tf32=378.0, bf16=756.0, fp16=756.0)),
    ('H200 NVL', dict(tf32=417.5, bf16=835.0, fp16=835.0)),
    ('H100', dict(tf32=494.7, bf16=989.4, fp16=989.4)),
    ('H200', dict(tf32=494.7, bf16=989.4, fp16=989.4)),  # and GH200
    ('GB200', dict(tf32=1250.0, bf16=2500.0, fp16=2500.0)),
    ('B200', dict(tf32=1125.0, bf16=2250.0, fp16=2250.0)),
    ('A100', dict(tf32=156.0, bf16=312.0, fp16=312.0)),
    ('L40S', dict(tf32=183.0, bf16=362.05, fp16=362.05)),
)
#: the Triton band kernels' names, as the profiler reports them
BAND_KERNELS = ('band_forward', 'band_backward')


class Interval(NamedTuple):
    """One kernel's run on the device: name, start and end in
    microseconds."""
    name: str
    start_us: float
    end_us: float


def peak_tflops(device_name: str, precision: str) -> Optional[float]:
    """The dense peak of a device from :data:`PEAK_TFLOPS` (the first
    entry whose key ``device_name`` contains), at ``precision``; ``None``
    when unknown."""
    for key, peaks in PEAK_TFLOPS:
        if key in device_name:
            return peaks.get(precision)
    return None


def band_kernel_flops(kernel: str, positions: int, hidden: int) -> float:
    """The ``H x H`` products' FLOPs of one launch of a band kernel over
    ``positions`` coefficient positions (pixels times coefficients)."""
    products = 3 if kernel == 'band_backward' else 1
    return products * 2.0 * 3 * hidden * hidden * positions


def summarize(intervals: Sequence[Interval], positions: int, hidden: int,
              peak: Optional[float]) -> Dict[str, object]:
    """The pass's kernels: ``span_ms`` (first start to last end),
    ``gaps_ms`` (the span no kernel covers), and one row per kernel name,
    longest first: ``kernel``, ``launches``, ``ms``, ``share`` of the span
    and, for the band kernels, ``tflops`` and ``of_peak`` (``None`` where
    ``peak`` is unknown)."""
    if not intervals:
        return dict(span_ms=0.0, gaps_ms=0.0, rows=[])
    ordered = sorted(intervals, key=lambda i: i.start_us)
    span = ordered[-1].end_us - ordered[0].start_us
    covered, reach = 0.0, ordered[0].start_us
    for interval in ordered:  # the union of the intervals
        covered += max(0.0, interval.end_us - max(reach, interval.start_us))
        reach = max(reach, interval.end_us)
    rows: Dict[str, Dict[str, object]] = {}
    for interval in ordered:
        row = rows.setdefault(interval.name, dict(
            kernel=interval.name, launches=0, ms=0.0))
        row['launches'] += 1
        row['ms'] += (interval.end_us - interval.start_us) / 1e3
    for row in rows.values():
        row['share'] = row['ms'] / (span / 1e3) if span else None
        band = next((k for k in BAND_KERNELS if k in row['kernel']), None)
        if band is not None and row['ms']:
            flops = band_kernel_flops(band, positions, hidden) * \
                row['launches']
            row['tflops'] = flops / (row['ms'] / 1e3) / 1e12
            row['of_peak'] = None if peak is None else row['tflops'] / peak
    return dict(span_ms=span / 1e3, gaps_ms=(span - covered) / 1e3,
                rows=sorted(rows.values(), key=lambda r: -r['ms']))


def profile_pass(shape: Sequence[int], device: str,
                 precision: str = 'tf32') -> Dict[str, object]:
    """One WGSE forward+backward of a ``(B, T, H, W)`` batch of spikes on a
    CUDA ``device`` at ``precision`` (``'tf32'``, or ``'bf16'``/``'fp16'``
    autocast), profiled after one warm-up pass: :func:`summarize`'s result
    with ``device``, ``precision``, ``backend`` (what ran), ``positions``
    (coefficient positions of the pass) and ``hidden`` (channels)."""
    from wgse_mmseg.core.wavelets import band_lengths
    from wgse_mmseg.core.wgse import WGSE
    if not torch.cuda.is_available() or not device.startswith('cuda'):
        raise ValueError(f'profiling a pass needs a CUDA device, not '
                         f'{device!r}')
    model = WGSE().to(device)
    batch, steps, height, width = shape
    spikes = (torch.rand(*shape, device=device) < 0.3).float()
    autocast = dict(bf16=torch.bfloat16, fp16=torch.float16).get(precision)

    def one_pass():
        with torch.autocast('cuda', dtype=autocast or torch.float16,
                            enabled=autocast is not None):
            out = model(spikes)
        out.backward(torch.ones_like(out))

    saved = torch.backends.cudnn.allow_tf32
    torch.backends.cudnn.allow_tf32 = precision != 'ieee'
    try:
        one_pass()  # compiles and checks
        torch.cuda.synchronize()
        activities = [torch.profiler.ProfilerActivity.CUDA]
        with torch.profiler.profile(activities=activities) as profiler:
            one_pass()
            torch.cuda.synchronize()
    finally:
        torch.backends.cudnn.allow_tf32 = saved
    intervals = [Interval(e.name, e.time_range.start, e.time_range.end)
                 for e in profiler.events()
                 if e.device_type == torch.autograd.DeviceType.CUDA]
    coefficients = sum(band_lengths(steps, model.wavelet, model.level,
                                    model.mode))
    name = torch.cuda.get_device_name(device)
    positions = batch * height * width * coefficients
    hidden = model.band_networks[0].hidden_channels
    return dict(summarize(intervals, positions, hidden,
                          peak_tflops(name, precision)),
                device=name, precision=precision,
                backend=model.backend_in_use, positions=positions,
                hidden=hidden)


def table_lines(profile: Dict[str, object]) -> List[str]:
    """Markdown lines of a :func:`profile_pass` result."""
    lines = ['| kernel | launches | ms | share | TFLOP/s | of peak |',
             '|---|--:|--:|--:|--:|--:|']
    for row in profile['rows']:
        tflops = row.get('tflops')
        of_peak = row.get('of_peak')
        lines.append(
            f"| `{row['kernel'][:70]}` | {row['launches']} | "
            f"{row['ms']:.3f} | {row['share']:.1%} | "
            f"{'' if tflops is None else f'{tflops:.1f}'} | "
            f"{'' if of_peak is None else f'{of_peak:.1%}'} |")
    lines.append(f"| gaps between kernels | | {profile['gaps_ms']:.3f} | "
                 f"{profile['gaps_ms'] / profile['span_ms']:.1%} | | |"
                 if profile['span_ms'] else '| gaps | | 0 | | | |')
    return lines
