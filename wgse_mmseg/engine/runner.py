"""The shipped configs' runner: mmengine's ``Runner`` that first gives the
config's ``num_steps`` to every field built from it
(:func:`wgse_mmseg.utils.num_steps.apply_num_steps`), writes each
checkpoint whole or not at all, and never executes config text a checkpoint
carries.

The configs name it (``runner_type = 'SpikeRunner'``), so MMSeg's own
``tools/train.py``, which builds ``RUNNERS.build(cfg)`` when a config has a
``runner_type``, uses it as this package's tools do.
"""
import os
import os.path as osp

from mmengine.dist import master_only
from mmengine.logging import print_log
# mmengine's root registry: RUNNERS.build(cfg) looks the runner up there
# (a config's default_scope is not in force yet)
from mmengine.registry import RUNNERS
from mmengine.runner import Runner

from ..utils.checkpoint import CheckpointError
from ..utils.num_steps import apply_num_steps

__all__ = ['SpikeRunner']


@RUNNERS.register_module()
class SpikeRunner(Runner):
    """:class:`~mmengine.runner.Runner` whose :meth:`from_cfg` applies
    ``cfg.num_steps`` first, whose :meth:`save_checkpoint` is atomic on
    local disks and whose :meth:`load_checkpoint` refuses config text that
    mmengine would execute; otherwise the same."""

    @classmethod
    def from_cfg(cls, cfg) -> 'SpikeRunner':
        changed = apply_num_steps(cfg)
        if changed:
            print_log(f'num_steps = {cfg.num_steps} applied to '
                      f'{", ".join(sorted(changed))} (they held '
                      f'{sorted(set(changed.values()))[0]}, from a base '
                      f'config)', logger='current')
        return super().from_cfg(cfg)

    def load_checkpoint(self, filename: str, *args, **kwargs) -> dict:
        """mmengine's, but a checkpoint with a ``meta['config']`` entry is
        refused (:class:`CheckpointError` naming the file): mmengine's
        :meth:`resume` executes that text (``Config.fromstring``) to compare
        GPU counts, so a checkpoint from elsewhere would run code. mmengine
        itself writes the config under ``meta['cfg']``, which nothing
        executes."""
        checkpoint = super().load_checkpoint(filename, *args, **kwargs)
        meta = checkpoint.get('meta')
        if isinstance(meta, dict) and 'config' in meta:
            raise CheckpointError(
                f"{filename}: meta['config'] holds config text, which "
                f"mmengine's resume would execute; a checkpoint is data and "
                f"this entry is refused (mmengine writes its config under "
                f"meta['cfg'])")
        return checkpoint

    @master_only
    def save_checkpoint(self, out_dir: str, filename: str, *args, **kwargs):
        """mmengine's, but on a local ``out_dir`` written under a temporary
        name and renamed over ``filename`` once whole: a job killed while it
        saves leaves the previous checkpoints and ``last_checkpoint`` (which
        mmengine's checkpoint hook updates after this returns) as they were,
        so ``--resume`` continues from the last complete checkpoint. Only
        the main process saves, as in mmengine."""
        if not osp.isdir(out_dir):  # a remote backend: as mmengine does it
            return super().save_checkpoint(out_dir, filename, *args,
                                           **kwargs)
        temporary = osp.join(osp.dirname(filename),
                             f'.tmp-{osp.basename(filename)}')
        super().save_checkpoint(out_dir, temporary, *args, **kwargs)
        os.replace(osp.join(out_dir, temporary), osp.join(out_dir, filename))
