"""WGSE on a GPU in one command, the most telling figures first: the
device's ceilings, each band kernel and the whole WGSE pass at TF32 and
bf16 beside the prediction, the first-use check 'auto' runs, a profiled
launch of each band kernel with its stall reasons, the tensor cores' rate
at the kernels' tiles, correctness against float64, then PSPNet and
SegFormer-B0 training steps raw and with WGSE, latency at batch 1, the
paper's shape and the targets of docs/gpu.md; writes gpu.md and gpu.json
(device, driver, versions).

    python dev/gpu_report.py              # CUDA: docs/gpu.md and gpu.json
    python dev/gpu_report.py --resume     # finish a run a time limit stopped
    python dev/gpu_report.py --dry-run    # CPU, tiny, into a temporary folder

On a GPU machine with torch alone: ``bash dev/gpu_report.sh`` (installs
``dev/gpu_bundle.sh``'s wheels, then runs this). What each section
measures: ``wgse_bench/gpu_report/``. A section that fails is recorded
with its error and the others still run; the exit status is 1 then. Both
files are rewritten after each section; a section starts only where the
time budget (``--budget``, seconds) has room for it, and the rest are left
"not run". ``--resume`` keeps the finished sections where the earlier run
measured the same plan and code on the same machine and software, and
measures the rest. ``--dry-run`` runs every section's code on the CPU at
tiny shapes (Triton in its interpreter, what needs CUDA skipped with the
reason), never into docs/, which holds the last GPU run.
"""
import argparse
import os
import os.path as osp
import sys
import tempfile

from wgse_mmseg.fileio.input_guard import keeps_inputs
from wgse_mmseg.fileio.locks import own_folder
from wgse_mmseg.fileio.output_folder import check_tool_outputs

ROOT = osp.dirname(osp.dirname(osp.abspath(__file__)))
#: docs/gpu.md's targets on one H100 or H200: figure
#: (``wgse_bench.gpu_report.targets.FIGURES``) -> (at most, aim or None)
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
#: seconds a GPU run takes at most unless --budget says otherwise: what a
#: session's device time leaves for the report and a resumed run
GPU_BUDGET_S = 420


def build_parser() -> argparse.ArgumentParser:
    # imported here, after main() has chosen Triton's interpreter for
    # --dry-run (the package's kernels import triton where they are loaded)
    from wgse_mmseg.command_line import Number, Path
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--dry-run', action='store_true',
                        help="every section's code on the CPU at tiny "
                        'shapes, Triton in its interpreter (what the tests '
                        'run before a GPU session)')
    parser.add_argument('--out-dir', type=Path(),
                        help='where gpu.md and gpu.json go (default: docs/; '
                        'with --dry-run a new temporary folder)')
    parser.add_argument('--budget', type=Number(0, strict_minimum=True),
                        help='seconds the run may take (default: '
                        f'{GPU_BUDGET_S} on a GPU, none with --dry-run): a '
                        'section starts only where its expected time fits')
    parser.add_argument('--resume', action='store_true',
                        help="keep the sections of OUT_DIR/gpu.json that an "
                        'earlier run of the same plan and code on this '
                        'machine and software finished; measure the rest')
    return parser


@keeps_inputs
def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if '--dry-run' in argv:  # before triton is first imported
        os.environ['TRITON_INTERPRET'] = '1'
    parser = build_parser()
    args = parser.parse_args(argv)
    docs = osp.join(ROOT, 'docs')
    if args.dry_run and args.out_dir and \
            osp.realpath(args.out_dir) == osp.realpath(docs):
        parser.error(f'--out-dir {args.out_dir}: docs/ holds the last GPU '
                     "run's report, not a dry run's CPU figures")
    if args.dry_run and args.resume and args.out_dir is None:
        parser.error('--resume with --dry-run needs the --out-dir of the '
                     'dry run it resumes')
    if args.out_dir is None:
        args.out_dir = tempfile.mkdtemp(prefix='gpu_report_') \
            if args.dry_run else docs
    check_tool_outputs(args, 'out_dir')
    import torch

    from wgse_bench import gpu_report
    if not args.dry_run and not torch.cuda.is_available():
        print('gpu_report.py: torch sees no CUDA device here (--dry-run '
              'runs the CPU check)', file=sys.stderr)
        return 2
    plan = gpu_report.DRY_RUN if args.dry_run else gpu_report.GPU
    budget = args.budget if args.budget is not None or args.dry_run \
        else GPU_BUDGET_S
    command = 'python dev/gpu_report.py' + (
        ' --dry-run' if args.dry_run else '')
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
                report, args.out_dir, command), budget_s=budget)
    print(f'wrote {osp.join(args.out_dir, "gpu.md")} and gpu.json')
    failed = [name for name, section in report['sections'].items()
              if section['status'] != 'ok']
    if failed:
        print(f'sections not all ok: {", ".join(failed)}', file=sys.stderr)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
