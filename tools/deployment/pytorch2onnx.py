"""Export a trained spike segmentor, enhancer included, to ONNX.

    python tools/deployment/pytorch2onnx.py CONFIG CHECKPOINT --shape T H W
        [--out FILE] [--opset 18] [--no-verify] [--seed 1] [--wait]
        [--cfg-options num_steps=41 ...]

One graph maps float spikes ``(batch, T, H, W)`` to logits ``(batch, K, H,
W)``: the config's enhancer (WGSE, TFP, the mean filters), the segmentor
and the final resize (``wgse_mmseg.apis.onnx_export``). ``T``, ``H`` and
``W`` are fixed; the batch is dynamic. The checkpoint is read weights-only
and must fit the config exactly (``--cfg-options num_steps=T`` for another
``T``); its classes and palette are checked before anything is written.
The file (default ``<config name>.onnx``) is written whole or not at all,
by one export at a time (a second export to the same file stops naming
the first, or waits with ``--wait``:
:func:`~wgse_mmseg.fileio.locks.own_folder`), and verified before it
is published: its interface is checked, and, unless ``--no-verify``, ONNX
Runtime (CPU) runs it on two random Bernoulli streams beside the torch
model; the largest logit difference and the share of pixels with the same
class are printed, and beyond ``LOGITS_TOLERANCE`` or below
``MIN_ARGMAX_AGREEMENT`` the tool exits with status 1 and writes no file
(one already at ``--out`` is left as it was).
"""
import argparse
import contextlib
import os.path as osp
import sys

from wgse_mmseg.apis.onnx_settings import (LOGITS_TOLERANCE,
                                           MIN_ARGMAX_AGREEMENT, OPSET, OPSETS,
                                           SHAPE_ENTRY)
from wgse_mmseg.command_line import SEED, Path
from wgse_mmseg.fileio.locks import add_wait_option, own_folder
from wgse_mmseg.fileio.input_guard import check_output_kind, keeps_inputs
from wgse_mmseg.fileio.output_folder import check_tool_outputs
from wgse_mmseg.utils.config import add_config_options

#: streams of the check against the torch model
VERIFY_BATCH = 2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description='Export a spike segmentor (enhancer included) to ONNX')
    parser.add_argument('config', type=Path(), help='config file')
    parser.add_argument('checkpoint', type=Path(), help='checkpoint file')
    parser.add_argument('--shape', type=SHAPE_ENTRY, nargs=3, required=True,
                        metavar=('T', 'H', 'W'),
                        help='the input the graph takes: T (the config\'s '
                        'num_steps) and the frame height and width')
    parser.add_argument('--out', type=Path(),
                        help='output file (default: <config name>.onnx)')
    parser.add_argument('--opset', type=OPSETS, default=OPSET,
                        help=f'ONNX opset ({OPSETS.minimum} to '
                        f'{OPSETS.maximum}; default {OPSET})')
    parser.add_argument('--no-verify', action='store_true',
                        help='skip the check against the torch model in '
                        'ONNX Runtime')
    parser.add_argument('--seed', type=SEED, default=1,
                        help='seed of the random spikes of the check')
    add_wait_option(parser)
    add_config_options(parser)
    return parser


@keeps_inputs
def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    # torch, ONNX and OpenMMLab once the arguments are read (--help at once)
    import wgse_mmseg
    wgse_mmseg.register_all_modules()  # before mmseg is imported
    from mmengine.registry import init_default_scope

    from wgse_mmseg.apis.onnx_export import (SpikeSegmentorGraph,
                                             compare_with_onnx, export_onnx,
                                             random_spikes)
    from wgse_mmseg.apis.segmentor_checkpoint import load_segmentor
    from wgse_mmseg.utils.config import load_config
    num_steps, height, width = args.shape
    out = args.out = args.out or \
        osp.splitext(osp.basename(args.config))[0] + '.onnx'
    check_tool_outputs(args, 'out')
    cfg = load_config(args.config, args.cfg_options)
    if cfg.get('num_steps') != num_steps:
        sys.exit(f'pytorch2onnx.py: error: --shape T={num_steps} but the '
                 f'config is built for num_steps={cfg.get("num_steps")}; '
                 f'add --cfg-options num_steps={num_steps}')
    init_default_scope(cfg.get('default_scope', 'mmseg'))
    try:
        model, dataset_meta = load_segmentor(cfg, args.checkpoint)
    except (ValueError, FileNotFoundError) as err:
        sys.exit(f'pytorch2onnx.py: error: {err}')
    graph = SpikeSegmentorGraph(model)
    spikes = random_spikes((VERIFY_BATCH, num_steps, height, width),
                           args.seed)
    verdicts = []

    def compare(written: str) -> None:
        """The comparison with the torch model, on the file before it is
        published: one that fails it is not left behind."""
        found = compare_with_onnx(graph, written, spikes)
        verdicts.append(found['ok'])
        print(f"onnxruntime against torch: max |logits difference| "
              f"{found['max_abs_diff']:.3g} (tolerance "
              f"{LOGITS_TOLERANCE * found['scale']:.3g}), argmax agreement "
              f"{100 * found['argmax_agreement']:.3f}% (at least "
              f"{100 * MIN_ARGMAX_AGREEMENT:.1f}%): "
              f"{'ok' if found['ok'] else 'FAILED'}")
        if not found['ok']:
            raise ValueError(f'{out}: not written, the exported graph does '
                             f'not agree with the torch model')

    # one export to a file at a time; a FIFO or device (streamed) needs no
    # lock, which would be a file beside it (in /dev)
    streamed = check_output_kind(out) is not None
    try:
        with contextlib.nullcontext() if streamed else own_folder(
                osp.dirname(osp.abspath(out)), osp.basename(out), args.wait,
                claim=False):
            export_onnx(graph, out, num_steps, height, width,
                        opset=args.opset, dataset_meta=dataset_meta,
                        check=None if args.no_verify else compare)
    except ValueError as err:
        if verdicts and not verdicts[-1]:
            print(f'pytorch2onnx.py: error: {err}', file=sys.stderr)
            return 1
        sys.exit(f'pytorch2onnx.py: error: {err}')
    print(f'{out}\tinput spikes (batch, {num_steps}, {height}, {width})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
