"""WGSE on a GPU in one command: correctness against float64, WGSE
forward+backward per backend, the first-use check 'auto' runs, PSPNet and
SegFormer-B0 training steps raw and with WGSE, latency at batch 1, the
paper's shape and the targets of docs/gpu.md; writes
gpu.md and gpu.json (device, driver, versions).

    python dev/gpu_report.py              # CUDA: docs/gpu.md and gpu.json
    python dev/gpu_report.py --resume     # finish a run a time limit stopped
    python dev/gpu_report.py --smoke --out-dir DIR  # CPU, Triton interpreted

On a GPU machine with torch alone: ``bash dev/gpu_report.sh`` (installs
``dev/gpu_bundle.sh``'s wheels, then runs this). What each section
measures: ``wgse_bench/gpu_report.py``. A section that fails is
recorded with its error and the others still run; the exit status is 1 then.
Both files are rewritten after each section, so a run stopped part-way (a time
limit) leaves what it measured; ``--resume`` keeps those sections where the
earlier run measured the same plan and code on the same machine and software,
and measures the rest.
"""
import argparse
import os
import os.path as osp
import sys

from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.fileio.locks import own_folder
from wgse_mmseg.fileio.output_folder import check_tool_outputs

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: docs/gpu.md's targets on one H100 or H200 (issue 43): figure
#: (``gpu_report.FIGURES``) -> (at most, aim or None)
TARGETS = {
    'wgse_ms': (25, 8),
    'wgse_bf16_ms': (15, 8),
    'wgse_gib': (1.5, None),
    'step_ratio': (1.3, 1.15),
    'step_ratio_amp': (1.3, 1.15),
    'segformer_step_ratio': (1.5, None),
    'added_latency_ms': (3, None),
    'paper_gb': (24, None),
    'paper_memory_ratio': (1.2, None),
    'first_use_s': (20, None),
}


def build_parser() -> argparse.ArgumentParser:
    # imported here, after main() has chosen Triton's interpreter for
    # --smoke (the package's kernels import triton where they are loaded)
    from wgse_mmseg.command_line import Path
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--smoke', action='store_true',
                        help='the same code on the CPU at tiny shapes, '
                        'Triton in its interpreter (what CI runs)')
    parser.add_argument('--out-dir', type=Path(),
                        default=osp.join(ROOT, 'docs'),
                        help='where gpu.md and gpu.json go (default: docs/)')
    parser.add_argument('--resume', action='store_true',
                        help="keep the sections of OUT_DIR/gpu.json that an "
                        'earlier run of the same plan and code on this '
                        'machine and software finished; measure the rest')
    return parser


@keeps_inputs
def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if '--smoke' in argv:  # before triton is first imported
        os.environ['TRITON_INTERPRET'] = '1'
    args = build_parser().parse_args(argv)
    check_tool_outputs(args, 'out_dir')
    import torch

    from wgse_bench import gpu_report
    if not args.smoke and not torch.cuda.is_available():
        print('gpu_report.py: torch sees no CUDA device here (--smoke runs '
              'the CPU check)', file=sys.stderr)
        return 2
    plan = gpu_report.SMOKE if args.smoke else gpu_report.GPU
    command = 'python dev/gpu_report.py' + (
        ' --smoke' if args.smoke else '')
    with own_folder(args.out_dir, 'gpu_report', claim=False):
        earlier = None
        path = osp.join(args.out_dir, 'gpu.json')
        if args.resume and osp.exists(path):
            try:
                earlier = gpu_report.read_report(path)
            except ValueError as err:
                sys.exit(f'gpu_report.py: error: --resume: {err}')
        report = gpu_report.run_report(
            plan, ROOT, TARGETS, earlier=earlier,
            save=lambda report: gpu_report.write_report(
                report, args.out_dir, command))
    print(f'wrote {osp.join(args.out_dir, "gpu.md")} and gpu.json')
    failed = [name for name, section in report['sections'].items()
              if section['status'] != 'ok']
    if failed:
        print(f'sections not all ok: {", ".join(failed)}', file=sys.stderr)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
