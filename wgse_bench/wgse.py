"""WGSE forward+backward time and peak memory against the reference design.

What ``tools/analysis_tools/benchmark_wgse.py`` runs; its docstring says
what is compared and how (docs/wgse_speed.md has the tables). Needs torch
and, for the reference row, ``pytorch_wavelets``; nothing of OpenMMLab, so
it runs on a GPU machine that has torch alone. Every measurement runs in a
fresh process (``python -m wgse_bench.wgse --worker ...``).

Its ``'reference'`` row is the public implementation's design
(:class:`ReferenceWGSE`), the baseline of the speed-ups; WGSE's own
``backend='reference'`` (the band networks' ``nn.Conv`` modules, for
tests) is not a row.
"""
import argparse
import json
import resource
import statistics
import subprocess
import sys
from typing import Dict, List, Optional

import torch

from wgse_mmseg.fileio.atomic import atomic_output
from wgse_mmseg.core.wgse import WGSE, band_network_backends

from .machine import machine_record
from .timing import time_calls
from .wgse_choices import IMPLEMENTATIONS, SHAPE


class ReferenceWGSE(torch.nn.Module):
    """The reference design around ``model``'s band networks: ``(B, T, H, W)``
    -> ``(B, T', H, W)`` with ``T' = T + 1`` for odd ``T``."""

    def __init__(self, model):
        super().__init__()
        from pytorch_wavelets import DWT1DForward, DWT1DInverse
        self.dwt = DWT1DForward(J=model.level, wave=model.wavelet, mode='zero')
        self.idwt = DWT1DInverse(wave=model.wavelet, mode='zero')
        self.band_networks = model.band_networks
        #: the WGSE module whose band networks this shares (not a submodule)
        self.__dict__['wgse'] = model

    def forward(self, spikes: torch.Tensor) -> torch.Tensor:
        batch, steps, height, width = spikes.shape
        signals = spikes.permute(0, 2, 3, 1).reshape(-1, 1, steps)
        low, highs = self.dwt(signals)
        low = self.band_networks[0](low)
        # pytorch_wavelets orders details finest first; WGSE's bands are
        # [cA_n, cD_n, ..., cD_1], PyWavelets' order.
        highs = [net(h) for net, h in zip(self.band_networks[1:],
                                          reversed(highs))]
        out = self.idwt((low, list(reversed(highs))))
        return out.reshape(batch, height, width, -1).permute(0, 3, 1, 2)


def available_backends(device: str) -> List[str]:
    """The backends of :data:`IMPLEMENTATIONS` that can run WGSE's default
    network on ``device``."""
    networks = WGSE().band_networks
    probe = torch.zeros(1, 1, sum(1 for _ in networks), device=device)
    return [name for name, backend in band_network_backends.BACKENDS.items()
            if name in IMPLEMENTATIONS and name != 'reference'
            and backend.cannot_run(networks, probe) is None]


def _build(impl: str, shape: List[int], device: str):
    torch.manual_seed(0)
    model = WGSE(backend='auto' if impl == 'reference' else impl)
    spikes = (torch.rand(shape, generator=torch.Generator().manual_seed(1))
              < 0.3).float().to(device)
    model.to(device)
    if impl == 'reference':
        return ReferenceWGSE(model).to(device), spikes
    return model, spikes


def _output_gradient(model, spikes: torch.Tensor) -> torch.Tensor:
    """A fixed random gradient for the pass's output ``(B, T', H, W)``, made
    before anything is measured, as a segmentor's backward pass hands WGSE
    one (a loss such as ``mean(out²)`` would add output-sized temporaries
    of its own backward to the peak: three at once for ``pow``)."""
    batch, steps, height, width = spikes.shape
    if isinstance(model, ReferenceWGSE):
        steps += steps % 2
    return torch.randn(batch, steps, height, width,
                       generator=torch.Generator().manual_seed(2)).to(
                           spikes.device)


def _step(model, spikes: torch.Tensor, grad: torch.Tensor) -> torch.Tensor:
    out = model(spikes)
    out.backward(grad)
    return out


def worker(impl: str, shape: List[int], repeat: int, device: str) -> Dict:
    """Measure one implementation at one shape (run in a fresh process)."""
    model, spikes = _build(impl, shape, device)
    grad = _output_gradient(model, spikes)
    if device == 'cuda':
        torch.cuda.synchronize()
        torch.cuda.reset_peak_memory_stats()
        before = torch.cuda.memory_allocated()
        _step(model, spikes, grad)
        peak_mib = (torch.cuda.max_memory_allocated() - before) / 2**20
    else:
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        _step(model, spikes, grad)
        peak_mib = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss -
                    before) / 1024
    # the first step above was the warm-up
    times = time_calls(lambda: (model.zero_grad(set_to_none=True),
                                _step(model, spikes, grad)),
                       device, repeat, warmup=0).wall
    pixels = shape[0] * shape[2] * shape[3]
    return dict(impl=impl, backend=getattr(model, 'backend_in_use', None),
                shape=shape, device=device, peak_mib=peak_mib,
                kib_per_pixel=peak_mib * 1024 / pixels,
                median_s=statistics.median(times), min_s=min(times),
                max_s=max(times), repeat=repeat)


def agreement(shape: List[int], device: str) -> Dict:
    """Max |WGSE - reference| over the output (the reference's extra sample
    for odd T dropped) and the band networks' gradients, same weights."""
    reference, spikes = _build('reference', shape, device)
    model = reference.wgse
    results = []
    for module in (model, reference):
        model.zero_grad(set_to_none=True)
        out = module(spikes)[:, :shape[1]]
        out.square().mean().backward()
        results.append((out.detach(), [p.grad.clone()
                                       for p in model.parameters()]))
    (out, grads), (ref_out, ref_grads) = results
    grad_err = max(((g - r).abs().max() / r.abs().max().clamp_min(1e-12)
                    ).item() for g, r in zip(grads, ref_grads))
    return dict(shape=shape, backend=model.backend_in_use,
                max_abs_output_diff=(out - ref_out).abs().max().item(),
                max_output=ref_out.abs().max().item(),
                max_rel_grad_diff=grad_err)


def run_worker(args: List[str]) -> Dict:
    """What ``--worker ARGS`` prints, from a fresh process."""
    cmd = [sys.executable, '-m', __name__, '--worker'] + args
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f'benchmark worker {args} failed:\n{proc.stderr}')
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run_benchmark(shapes: List[List[int]], impls: List[str], repeat: int,
                  device: str, out: Optional[str] = None) -> Dict:
    """Measure ``impls`` (``'reference'`` and backend names) at every shape,
    printing the table as rows come in; returns (and writes to ``out`` as
    JSON) ``{'machine', 'results', 'agreement'}``."""
    info = machine_record(device)
    print('WGSE forward+backward (db8, 5 levels, zero mode, kernel 3, '
          '32 channels)')
    print(' | '.join(f'{k}: {v}' for k, v in info.items()))
    header = (f'{"shape":>14} {"implementation":<40} {"median s":>9} '
              f'{"min-max s":>13} {"peak MiB":>9} {"KiB/px":>7} '
              f'{"speed-up":>9} {"memory":>7}')
    print(header)
    print('-' * len(header))
    rows, checks = [], []
    for shape in shapes:
        text = 'x'.join(map(str, shape))
        results = {impl: run_worker([impl, text, str(repeat),
                                     '--device', device])
                   for impl in impls}
        base = results.get('reference')
        for impl, res in results.items():
            speed = mem = ''
            if base and impl != 'reference':
                res['speedup'] = base['median_s'] / res['median_s']
                res['memory_ratio'] = res['peak_mib'] / max(base['peak_mib'],
                                                            1e-9)
                speed = f'{res["speedup"]:.1f}x'
                mem = f'{res["memory_ratio"]:.2f}'
            print(f'{text:>14} {IMPLEMENTATIONS[impl]:<40} '
                  f'{res["median_s"]:>9.3f} '
                  f'{res["min_s"]:>6.3f}-{res["max_s"]:<6.3f} '
                  f'{res["peak_mib"]:>9.0f} {res["kib_per_pixel"]:>7.1f} '
                  f'{speed:>9} {mem:>7}')
            rows.append(res)
        if 'reference' in impls:
            check = run_worker(['agree', text, '--device', device])
            checks.append(check)
            print(f'{"":>14} output agreement ({check["backend"]}): max '
                  f'|WGSE - reference| = '
                  f'{check["max_abs_output_diff"]:.2e} (outputs up to '
                  f'{check["max_output"]:.2f}); band-network gradients: max '
                  f'relative difference {check["max_rel_grad_diff"]:.2e}')
    peak = ('CUDA memory allocated' if device == 'cuda' else
            'peak RSS')
    print('speed-up: reference median / median; memory: peak / reference '
          f'peak (peak = growth of {peak} during one forward+backward)')
    report = dict(machine=info, results=rows, agreement=checks)
    if out:
        with atomic_output(out) as f:
            f.write(json.dumps(report, indent=2).encode())
    return report


def _worker_main(argv: List[str]) -> int:
    """``--worker KIND SHAPE [REPEAT] --device DEVICE``: one measurement in
    this fresh process, printed as JSON."""
    parser = argparse.ArgumentParser()
    parser.add_argument('--worker', nargs='+', required=True)
    parser.add_argument('--device', default='cpu')
    args = parser.parse_args(argv)
    kind, *rest = args.worker
    if kind == 'agree':
        result = agreement(list(SHAPE(rest[0])), args.device)
    else:
        result = worker(kind, list(SHAPE(rest[0])), int(rest[1]),
                        args.device)
    print(json.dumps(result))
    return 0


if __name__ == '__main__':
    sys.exit(_worker_main(sys.argv[1:]))
