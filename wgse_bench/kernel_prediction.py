"""What the compiled Triton band kernels predict of a GPU's time, no GPU
needed.

Two models, both reading the code :mod:`.triton_resources` compiles:

* the issue floor (:func:`predicted_ms`): an SM issues at most one warp
  instruction per scheduler and clock, so the step loop's warp instructions
  per coefficient position give a lower bound on a pass's time at a GPU's
  clock; :func:`measured_against_predicted` sets that bound beside what a
  GPU report's profile measured (``--against gpu.json``);
* the prediction (:func:`predict_band_kernels`): the SASS run through
  :mod:`.sass_timing`'s model of one SM (what the floor leaves out:
  serialised products and their waits, barriers, the distance from a load
  to its use, the tensor pipe, the edge steps of each band), the programs
  then placed on the GPU's SMs (:func:`makespan`). Applied to the kernels
  this repository ran before (:func:`predict_former_kernels`) it explains
  their one measurement within :data:`PREDICTION_ERROR`.

The compiles run in a fresh process with ``TRITON_INTERPRET`` unset
(``python -m wgse_bench.kernel_prediction``). Figures: docs/wgse_speed.md,
"A predictor".
"""
import argparse
import json
import os
import sys
from typing import Dict, List, Optional, Sequence

from wgse_mmseg.command_line import Choice, Integer, Number, Path
from wgse_mmseg.limits import MAX_WORKERS

from . import sass_timing
from .triton_resources import (ARCHITECTURES, Variant, compile_and_disassemble,
                               compile_band_kernel, compile_rows,
                               programs_per_sm, refuse_interpreter,
                               resource_usage, resources_of, run_fresh,
                               training_variants)

__all__ = []


def predicted_ms(positions: float, instructions_per_position: float,
                 sms: int, clock_ghz: float, schedulers: int = 4) -> float:
    """The least time ``positions`` coefficient positions take at
    ``instructions_per_position`` warp instructions each, on ``sms`` SMs
    of ``schedulers`` issuing one warp instruction a clock each at
    ``clock_ghz``: every cycle issuing, none waiting."""
    return positions * instructions_per_position / (
        sms * schedulers * clock_ghz * 1e6)


def measured_against_predicted(report: Dict, rows: Sequence[Dict]
                               ) -> List[Dict]:
    """The band kernels a GPU report profiled, each beside the cost model's
    floor on the report's GPU. ``report``: the report's JSON (gpu.json, by
    :mod:`.gpu_report`; its ``profile`` section); ``rows``:
    :func:`~.triton_resources.compile_all`'s rows for the report's target.
    Per profiled
    precision and kernel: ``per_position`` (warp instructions a coefficient
    position), ``predicted_ms`` (:func:`predicted_ms` at the report's SMs
    and peak clock, times the kernel's launches), ``measured_ms`` and
    ``of_issue`` (predicted over measured: the share of the SMs' issue
    slots the kernel's instructions filled). The variants are the launch
    entries a training pass runs (no input gradient).

    Raises:
        ValueError: the report lacks what this needs (a GPU of one of
            :data:`~.triton_resources.ARCHITECTURES`, its SMs and clock, a
            profile), or ``rows`` holds no variant a profiled kernel ran.
    """
    env = report.get('environment') if isinstance(report, dict) else None
    if not isinstance(env, dict) or env.get('capability') not in \
            ARCHITECTURES or not env.get('sms') or \
            not env.get('sm_clock_mhz'):
        raise ValueError(
            f"the report names no GPU of {list(ARCHITECTURES)} with its SMs "
            f"and clock (environment's capability, sms, sm_clock_mhz; a "
            f"report from before they were recorded has no clock)")
    sections = report.get('sections')
    profile = sections.get('profile') if isinstance(sections, dict) else None
    measured = [r for r in profile.get('rows', []) if isinstance(r, dict)
                and r.get('status') == 'ok'] \
        if isinstance(profile, dict) else []
    if not measured:
        raise ValueError('the report has no profile of a WGSE pass (its '
                         "'profile' section did not run or failed)")
    try:
        return [row for run in measured
                for row in _against_floor(run, env, rows)]
    except (KeyError, TypeError) as err:
        raise ValueError(f"the report's profile is not as "
                         f'dev/gpu_report.py writes it ({err!r} missing or '
                         f'odd)') from err


def _against_floor(run: Dict, env: Dict, rows: Sequence[Dict]
                   ) -> List[Dict]:
    """:func:`measured_against_predicted`'s rows of one profiled pass."""
    from wgse_mmseg.core.kernel_choices import TOLERANCES
    from wgse_mmseg.core.wgse.triton_launch_choices import (FORWARD_CONFIGS,
                                                            backward_configs)
    if run['precision'] not in TOLERANCES:
        raise ValueError(f"the report's profile ran at precision "
                         f"{run['precision']!r}, not one of "
                         f'{list(TOLERANCES)}')
    entries = dict(band_forward=FORWARD_CONFIGS[0],
                   band_backward=backward_configs(False, run['precision'])[0])
    found = []
    for kernel_row in run.get('rows', []):
        kernel = next((k for k in entries if k in kernel_row['kernel']),
                      None)
        if kernel is None:
            continue
        entry = entries[kernel]
        compiled = [r for r in rows if r['arch'] == env['capability']
                    and r['kernel'] == kernel
                    and r['hidden'] == run['hidden']
                    and r['precision'] == run['precision']
                    and not r['input_grad']
                    and r['block'] == entry.block
                    and r['num_warps'] == entry.num_warps]
        if not compiled:
            raise ValueError(
                f"no compiled {kernel} for {env['capability']} at "
                f"{run['precision']}, {run['hidden']} channels, "
                f'{entry.name}')
        floor = kernel_row['launches'] * predicted_ms(
            run['positions'], compiled[0]['per_position'], env['sms'],
            env['sm_clock_mhz'] / 1e3)
        found.append(dict(
            precision=run['precision'], kernel=kernel,
            per_position=compiled[0]['per_position'],
            predicted_ms=floor, measured_ms=kernel_row['ms'],
            of_issue=floor / kernel_row['ms']))
    return found


def format_comparison(found: Sequence[Dict], report: Dict) -> str:
    """:func:`measured_against_predicted`'s rows as a Markdown table, the
    GPU named."""
    env = report['environment']
    lines = [f"{env.get('gpu', env['capability'])} ({env['capability']}, "
             f"{env['sms']} SMs at {env['sm_clock_mhz']:.0f} MHz, 4 "
             f'schedulers each):', '',
             '| precision | kernel | instr/position | issue floor ms '
             '| measured ms | of issue |',
             '|---|---|--:|--:|--:|--:|']
    lines += [f"| {r['precision']} | {r['kernel']} | "
              f"{r['per_position']:.1f} | {r['predicted_ms']:.2f} | "
              f"{r['measured_ms']:.2f} | {r['of_issue']:.0%} |"
              for r in found]
    return '\n'.join(lines)


#: Coefficients of each band of WGSE's paper at T = 129 (db8, 5 levels):
#: approximation, then details from the coarsest
PAPER_BANDS = (18, 18, 22, 29, 43, 72)
#: The predictor's largest relative error on the one measurement of these
#: kernels' kind there is (the former kernels on an H200; docs/wgse_speed.md,
#: "A predictor"), with a point of margin: what a prediction of
#: :func:`predict_band_kernels` is stated with
PREDICTION_ERROR = 0.21


def makespan(durations: Sequence[float], slots: int) -> float:
    """When the last of programs of ``durations`` (in launch order) ends on
    ``slots`` resident places, each program taking the first place free:
    how a GPU's block scheduler fills its SMs."""
    import heapq
    places = [0.0] * max(1, min(slots, len(durations)))
    for duration in durations:
        heapq.heappush(places, heapq.heappop(places) + duration)
    return max(places)


def _program_cycles(variant: Variant, arch: str, pixels: int,
                    hardware: sass_timing.Hardware):
    """:func:`.sass_timing.program_cycles` of ``variant`` compiled for
    ``arch``, on band-major rows of ``pixels`` pixels, with the programs an
    SM holds."""
    compiled, sass, dump = compile_and_disassemble(variant, arch)
    used = resources_of(variant, arch, compiled, sass, dump)
    layout = sass_timing.Layout(4, 4 * pixels, sass_timing.pixels_per_access(
        compiled.asm['ttgir'], variant.block))
    return sass_timing.program_cycles(sass, used.programs_per_sm,
                                      variant.num_warps, layout, hardware)


def _predict_here(precision: str, batch: int, pixels: int,
                  lengths: Sequence[int], hidden: int,
                  hardware: sass_timing.Hardware) -> Dict:
    """:func:`predict_band_kernels`, compiled in this process."""
    from wgse_mmseg.core.wgse.triton_launch_choices import work_division
    forward, backward = training_variants(precision, hidden)
    found = dict(gpu=hardware.name, sms=hardware.sms,
                 clock_ghz=hardware.clock_ghz, precision=precision,
                 error=PREDICTION_ERROR)
    for variant, extra in ((forward, 2), (backward, 3)):
        cycles = _program_cycles(variant, 'sm_90', pixels, hardware)
        tiles = batch * -(-pixels // variant.block)
        if variant.kernel == 'band_forward':  # a program a tile and band
            durations = [cycles(length + extra) for length in lengths
                         for _ in range(tiles)]
        else:  # persistent: each program every step-th tile of its band
            durations = [
                cycles.fixed + cycles.per_step * (lengths[band] + extra) *
                len(range(first, tiles, step)) for band, first, step in
                work_division(lengths, tiles,
                              hardware.sms * cycles.programs)]
        found[variant.kernel] = makespan(
            durations, hardware.sms * cycles.programs) / (
                hardware.clock_ghz * 1e6)
        found[f'{variant.kernel}_per_step_cycles'] = cycles.per_step
        found[f'{variant.kernel}_programs_per_sm'] = cycles.programs
    return found


def predict_band_kernels(precision: str = 'tf32', batch: int = 4,
                         height: int = 256, width: int = 512,
                         hidden: int = 32, sms: int = 132,
                         clock_ghz: float = 1.98) -> Dict:
    """The band kernels' predicted times on a Hopper GPU (sm_90: H100,
    H200) for one WGSE training pass, compiled here (no GPU).

    Each kernel's training variant at ``precision`` (``'tf32'``, ``'bf16'``,
    ``'fp16'``) is compiled for sm_90, and its SASS run through
    :mod:`.sass_timing`'s model of one SM (ptxas' control bits, published
    latencies and rates, the programs an SM holds); the forward's programs
    (one a tile and band) and the backward's persistent ones
    (:func:`~wgse_mmseg.core.wgse.triton_launch_choices.work_division`) are
    then placed on the GPU's ``sms`` SMs (:func:`makespan`). Runs in a
    fresh process with ``TRITON_INTERPRET`` unset.

    Args:
        precision: of the tensor-core products.
        batch, height, width: the spikes' ``B``, ``H``, ``W`` (the bands:
            :data:`PAPER_BANDS`, the paper's T = 129).
        hidden: the band networks' channels (16 or 32).
        sms, clock_ghz: the GPU's SMs and SM clock under load (default:
            the H200's).

    Returns:
        ``band_forward`` and ``band_backward``: predicted milliseconds of
        each kernel's launch (what ``torch.profiler`` reports per kernel);
        ``error``: the relative error to state them with
        (:data:`PREDICTION_ERROR`); the GPU's ``gpu``, ``sms``,
        ``clock_ghz``, the ``precision``, and per kernel its
        ``*_per_step_cycles`` (one SM, all its programs) and
        ``*_programs_per_sm``. The rest of a pass (the wavelet products,
        ``d3``, conv3's bias gradient) is not in it.

    Raises:
        ValueError: an argument out of range.
        RuntimeError: the kernels do not compile here.
    """
    from wgse_mmseg.core.kernel_choices import HIDDEN_CHANNELS, TOLERANCES
    if precision not in TOLERANCES or precision == 'ieee':
        raise ValueError(f'predict_band_kernels: precision must be one of '
                         f'the tensor-core ones {list(TOLERANCES)[1:]}, '
                         f'got {precision!r}')
    if hidden not in HIDDEN_CHANNELS:
        raise ValueError(f'predict_band_kernels: hidden must be one of '
                         f'{HIDDEN_CHANNELS}, got {hidden!r}')
    sizes = dict(batch=batch, height=height, width=width, sms=sms)
    bad = [k for k, v in sizes.items() if isinstance(v, bool) or
           not isinstance(v, int) or v < 1]
    if bad or isinstance(clock_ghz, bool) or not (
            isinstance(clock_ghz, (int, float)) and clock_ghz > 0):
        raise ValueError(f'predict_band_kernels: batch, height, width and '
                         f'sms must be positive integers and clock_ghz '
                         f'positive, got {sizes}, clock_ghz {clock_ghz!r}')
    return run_fresh(['--predict', precision, '--shape', str(batch),
                      str(height), str(width), '--hidden', str(hidden),
                      '--sms', str(sms), '--clock-mhz', str(clock_ghz * 1e3)],
                     __name__)


#: the former kernels' arguments (pixel-major ``(N, C)`` coefficients, a
#: launch a band, its length a constant)
_FORMER_SIGNATURES = {
    'band_forward': dict(x_ptr='*fp32', y_ptr='*fp32', stride='i32',
                         offset='i32', pixels='i32'),
    'band_backward': dict(x_ptr='*fp32', gy_ptr='*fp32', gx_ptr='*fp32',
                          partial_ptr='*fp32', stride='i32', offset='i32',
                          pixels='i32'),
}
#: the launch entries the former kernels ran on an H200 (its autotuner's
#: choice at 4x256x512 pixels): ``(block, warps)``, and the steps a band's
#: program takes beyond its length
_FORMER_ENTRIES = dict(band_forward=(64, 4, 2), band_backward=(16, 4, 5))


def predict_former_kernels(source: str, batch: int = 4, height: int = 256,
                           width: int = 512) -> Dict[str, Dict[str, float]]:
    """The predictor applied to the kernels this repository's Triton
    backend ran before its band-major rewrite (``source``: their module's
    path: ``_triton_band_kernels.py`` of ``wgse_mmseg/core/wgse`` at commit
    3123fe6, ``git show``)
    at TF32 and 32 channels on an H200: per kernel, each band length of
    :data:`PAPER_BANDS` (as a string: JSON's keys) mapped to the predicted
    milliseconds of its launch (a launch a band, pixel-major coefficients
    of ``sum(PAPER_BANDS)`` columns), by the same model and hardware figures
    as :func:`predict_band_kernels`. Runs in a fresh process with
    ``TRITON_INTERPRET`` unset."""
    return run_fresh(['--former', os.fspath(source), '--shape', str(batch),
                      str(height), str(width)], __name__)


def _predict_former_here(source: str, batch: int, pixels: int,
                         hidden: int, hardware: sass_timing.Hardware
                         ) -> Dict[str, Dict[int, float]]:
    """:func:`predict_former_kernels`, compiled in this process."""
    import importlib.util
    spec = importlib.util.spec_from_file_location('former_kernels', source)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    columns = sum(PAPER_BANDS)
    found: Dict[str, Dict[int, float]] = {}
    for kernel, (block, warps, extra) in _FORMER_ENTRIES.items():
        for length in sorted(set(PAPER_BANDS)):
            constants = dict(LENGTH=length, HIDDEN=hidden, BLOCK=block,
                             PRECISION='tf32')
            if kernel == 'band_backward':
                constants['INPUT_GRAD'] = False
            compiled, sass, dump = compile_band_kernel(
                getattr(module, kernel), _FORMER_SIGNATURES[kernel],
                constants, 90, dict(num_warps=warps))
            registers, _, shared, _ = resource_usage(
                dump, f'the former {kernel} at length {length}')
            programs = programs_per_sm(
                registers, warps, shared + compiled.metadata.shared,
                'sm_90')
            layout = sass_timing.Layout(
                4 * columns, 4, sass_timing.pixels_per_access(
                    compiled.asm['ttgir'], block))
            cycles = sass_timing.program_cycles(sass, programs, warps,
                                                layout, hardware)
            tiles = batch * -(-pixels // block)
            found.setdefault(kernel, {})[length] = makespan(
                [cycles(length + extra)] * tiles, hardware.sms * programs
            ) / (hardware.clock_ghz * 1e6)
    return found


def _report_of_this_code(path: str) -> Dict:
    """The report at ``path``, checked to have measured the code here (its
    digest), so that what is compiled here is what ran there."""
    from .gpu_report import code_digest, read_report
    report = read_report(path)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    environment = report.get('environment')
    measured = environment.get('code') \
        if isinstance(environment, dict) else None
    here = code_digest(root)
    if measured != here:
        raise ValueError(f'{path}: it measured other code (digest '
                         f'{measured}) than this checkout\'s ({here}); '
                         f'compiling this code would not predict that run')
    return report


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Predict the WGSE Triton band kernels\' times on a GPU '
        'from their code compiled here (no GPU needed): on a Hopper GPU '
        '(--predict), the former kernels on an H200 (--former), or the issue '
        'floor beside a GPU report\'s measurement (--against).')
    action = parser.add_mutually_exclusive_group()
    action.add_argument('--predict', metavar='PRECISION',
                        type=Choice(['tf32', 'bf16', 'fp16']),
                        help='the band kernels\' predicted times on a Hopper '
                        'GPU at this precision (predict_band_kernels)')
    action.add_argument('--former', metavar='SOURCE', type=Path('file'),
                        help='the former pixel-major kernels\' module '
                        '(git show 3123fe6:wgse_mmseg/core/wgse/'
                        '_triton_band_kernels.py): the predicted times of '
                        'their launches on an H200 at TF32')
    action.add_argument('--against', metavar='REPORT', type=Path(),
                        help="a GPU report's gpu.json (dev/gpu_report.py): "
                        'compile for its GPU and print each profiled band '
                        "kernel's measured time beside the issue floor, as "
                        'the share of issue it reached')
    parser.add_argument('--shape', nargs=3, metavar=('B', 'H', 'W'),
                        type=Integer(1, 1 << 16), default=[4, 256, 512],
                        help='with --predict or --former: the spikes\' '
                        'batch, height and width (default 4 256 512)')
    parser.add_argument('--hidden', type=Choice([16, 32]), default=32,
                        help='with --predict or --former: the band '
                        'networks\' channels')
    parser.add_argument('--sms', type=Integer(1, 1024), default=132,
                        help='with --predict: the GPU\'s SMs')
    parser.add_argument('--clock-mhz', type=Number(1, 10000,
                                                   strict_minimum=True),
                        default=1980.0,
                        help='with --predict: the GPU\'s SM clock under load')
    parser.add_argument('--jobs', type=Integer(1, MAX_WORKERS),
                        default=min(os.cpu_count() or 1, MAX_WORKERS),
                        help='with --against: compiles side by side')
    parser.add_argument('--json', action='store_true',
                        help='with --against: print the rows as JSON instead '
                        'of a table (the other actions always print JSON)')
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    refuse_interpreter(parser)
    if not (args.predict or args.former or args.against):
        parser.error('give one of --predict, --former and --against')
    batch, height, width = args.shape
    if args.predict:
        hardware = sass_timing.H200._replace(
            sms=args.sms, clock_ghz=args.clock_mhz / 1e3)
        print(json.dumps(_predict_here(args.predict, batch, height * width,
                                       PAPER_BANDS, args.hidden, hardware)))
        return 0
    if args.former:
        print(json.dumps(_predict_former_here(
            args.former, batch, height * width, args.hidden,
            sass_timing.H200)))
        return 0
    try:
        report = _report_of_this_code(args.against)
        capability = report.get('environment', {}).get('capability')
        rows = compile_rows([capability], args.jobs) \
            if capability in ARCHITECTURES else []
        found = measured_against_predicted(report, rows)
    except ValueError as err:
        parser.error(f'--against {args.against}: {err}')
    print(json.dumps(found) if args.json else
          format_comparison(found, report))
    return 0


if __name__ == '__main__':
    sys.exit(main())
