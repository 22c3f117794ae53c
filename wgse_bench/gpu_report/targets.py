"""The figures a report is judged by, read from its sections, and the
targets the caller gives them."""
from typing import Any, Dict, List, Optional, Tuple

__all__ = []

#: The figures a report can hold targets for: key -> (what, unit).
FIGURES = {
    'wgse_ms': ('WGSE forward+backward time, TF32', 'ms'),
    'wgse_bf16_ms': ('WGSE forward+backward time, bf16 autocast', 'ms'),
    'wgse_gib': ('WGSE forward+backward peak memory', 'GiB'),
    'step_ratio': ('PSPNet + WGSE step / raw step', 'x'),
    'step_ratio_amp': ('PSPNet + WGSE step / raw step, AMP (fp16)', 'x'),
    'segformer_step_ratio': ('SegFormer-B0 + WGSE step / raw step', 'x'),
    'added_latency_ms': ('PSPNet latency added by WGSE (batch 1)', 'ms'),
    'paper_gb': ("PSPNet + WGSE step at the paper's shape, peak memory",
                 'GB'),
    'paper_memory_ratio': ("PSPNet + WGSE / raw step's peak memory at the "
                           "paper's shape", 'x'),
    'first_use_s': ("the first-use check's longest wait (compiles and "
                    'checks)', 's'),
}
#: Targets: figure key -> (at most, a moonshot or None).
Targets = Dict[str, Tuple[float, Optional[float]]]


def _rows(sections: Dict[str, Dict], name: str) -> List[Dict[str, Any]]:
    """A section's rows, none where it was not measured."""
    return sections.get(name, {}).get('rows', [])


def figures(sections: Dict[str, Dict]) -> Dict[str, Optional[float]]:
    """Each of :data:`FIGURES` in a report's ``sections``, ``None`` where it
    was not measured. WGSE's figures are those of the backend ``'auto'``
    runs on the device: Triton on CUDA, else the compiled or the torch
    one."""
    passes = {(r['impl'], r.get('precision')): r
              for r in _rows(sections, 'wgse') if r['status'] == 'ok'}

    def wgse(precision: str) -> Optional[Dict[str, Any]]:
        return next((passes[(impl, precision)] for impl in
                     ('triton', 'compiled', 'torch')
                     if (impl, precision) in passes), None)

    def step(model: str, enhancer: str) -> Dict[str, Any]:
        return next((r for r in _rows(sections, 'segmentation')
                     if r['model'] == model and r['enhancer'] == enhancer),
                    {})

    tf32, bf16 = wgse('tf32'), wgse('bf16')
    pspnet = step('PSPNet R50-D8', 'WGSE')
    paper = [r for r in _rows(sections, 'paper')
             if r['status'] == 'ok' and r['enhancer'] == 'WGSE']
    waits = [r['seconds'] for r in _rows(sections, 'first_use')
             if r.get('seconds') is not None]
    return dict(
        wgse_ms=None if tf32 is None else tf32['median_ms'],
        wgse_bf16_ms=None if bf16 is None else bf16['median_ms'],
        wgse_gib=None if tf32 is None or tf32.get('peak_mib') is None
        else tf32['peak_mib'] / 1024,
        step_ratio=pspnet.get('step_vs_raw'),
        step_ratio_amp=step('PSPNet R50-D8', 'WGSE, AMP').get('step_vs_raw'),
        segformer_step_ratio=step('SegFormer-B0', 'WGSE').get('step_vs_raw'),
        added_latency_ms=pspnet.get('added_latency_ms'),
        paper_gb=(paper[0]['memory']['peak_mb'] * 2**20 / 1e9
                  if paper else None),
        paper_memory_ratio=paper[0].get('memory_vs_raw') if paper else None,
        first_use_s=max(waits) if waits else None)


def judge(sections: Dict[str, Dict], targets: Targets
          ) -> List[Dict[str, Any]]:
    """Each of ``targets`` with the figure of this report (``None`` where
    it was not measured) and whether it is met: ``what``, ``unit``,
    ``target``, ``moonshot``, ``value``, ``met``, ``moonshot_met``."""
    found = figures(sections)
    rows = []
    for key, (limit, moonshot) in targets.items():
        what, unit = FIGURES[key]
        value = found[key]
        rows.append(dict(what=what, unit=unit, target=limit,
                         moonshot=moonshot, value=value,
                         met=None if value is None else value <= limit,
                         moonshot_met=None if value is None or
                         moonshot is None else value <= moonshot))
    return rows
