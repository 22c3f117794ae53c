"""The shipped configs' runner: mmengine's ``Runner`` that first gives the
config's spike settings (``num_steps``, ``data_root``, ``crop_size``) to
the fields that carry them
(:func:`wgse_mmseg.utils.spike_settings.apply_spike_settings`), trains in a
work dir no other training writes, writes each checkpoint whole or not at
all, never executes config text a checkpoint carries, and formats its
config's text once (mmengine formats it with yapf, about 0.5 s on a CPU,
each time a run logs, dumps or checkpoints it: four times or more a
training).

The configs name it (``runner_type = 'SpikeRunner'``), so MMSeg's own
``tools/train.py``, which builds ``RUNNERS.build(cfg)`` when a config has a
``runner_type``, uses it as this package's tools do.
"""
import contextlib
import copy
import logging
import os.path as osp
import pickle

from mmengine.config import Config
from mmengine.dist import broadcast_object_list, is_main_process, master_only
from mmengine.logging import print_log
from mmengine.model import BaseTTAModel
# mmengine's root registry: RUNNERS.build(cfg) looks the runner up there
# (a config's default_scope is not in force yet)
from mmengine.registry import RUNNERS
from mmengine.runner import Runner

from .._openmmlab import prepare_mmseg_layer
from ..fileio.atomic import atomic_path, temporaries_of
from ..fileio.input_guard import OutputFolderError
from ..fileio.locks import own_folder
from ..fileio.output_folder import discard, unshare
from ..utils.checkpoint import CheckpointError, load_error
from ..models.data_preprocessor import (SpikeModelMismatchError,
                                        unfit_weights)
from ..utils.cross_checks import check_model_fits, check_training_fits
from ..utils.distributed import fit_to_cpus, fit_workers
from ..utils.spike_settings import apply_spike_settings

__all__ = ['SpikeRunner']


class _FormattedOnce(Config):
    """A :class:`~mmengine.config.Config` whose ``pretty_text`` is
    mmengine's, formatted once for each content: the unformatted text
    (mmengine's own, without yapf; milliseconds) is the key, so a config
    changed after its text was formatted is formatted again."""

    @property
    def pretty_text(self) -> str:
        formatting = self._format_python_code
        if not formatting:
            return Config.pretty_text.fget(self)
        object.__setattr__(self, '_format_python_code', False)
        try:
            unformatted = Config.pretty_text.fget(self)
        finally:
            object.__setattr__(self, '_format_python_code', formatting)
        cached = self.__dict__.get('_formatted')
        if cached is None or cached[0] != unformatted:
            cached = (unformatted, Config.pretty_text.fget(self))
            object.__setattr__(self, '_formatted', cached)
        return cached[1]

    @classmethod
    def of(cls, cfg: Config) -> '_FormattedOnce':
        """``copy.copy(cfg)`` (mmengine's copy) as this class."""
        formatted = cls.__new__(cls)
        formatted.__dict__.update(copy.copy(cfg).__dict__)
        return formatted


#: what mmengine logs at every run that no user can act on: the deprecation
#: of a file client MMSeg itself uses, and a metric's empty prefix
_UNACTIONABLE = ('"FileClient" will be deprecated',
                 'is the alias of "LocalBackend"',
                 'The prefix is not set in metric class')


class _Unactionable(logging.Filter):
    """Drops :data:`_UNACTIONABLE` records from the run's log."""

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        return not any(text in message for text in _UNACTIONABLE)


@RUNNERS.register_module()
class SpikeRunner(Runner):
    """:class:`~mmengine.runner.Runner` whose :meth:`from_cfg` sets up the
    MMSeg layer (as :func:`wgse_mmseg.register_all_modules` does, once per
    process) and applies the config's spike settings first (also those
    ``--cfg-options`` of MMSeg's own tools merged in), fits the config to a
    machine without GPUs (every SyncBN of the model as BN) and to
    ``num_workers=0`` (``persistent_workers`` off), and formats the
    config's text once for all its uses, whose :meth:`train` first checks
    that the crop and the batch fit the model
    (:class:`~wgse_mmseg.utils.cross_checks.ModelFitError` where not) and
    owns the work dir while it trains, whose :meth:`save_checkpoint` is
    atomic on local disks and whose :meth:`load_checkpoint` refuses config
    text that mmengine would execute; otherwise the same."""

    @classmethod
    def from_cfg(cls, cfg) -> 'SpikeRunner':
        prepare_mmseg_layer('SpikeRunner')  # resuming needs the allowlist
        changed = apply_spike_settings(cfg)
        if changed:
            print_log('spike settings applied (the fields held a base '
                      "config's values): " + ', '.join(
                          f'{path} (was {old!r})' for path, old in
                          sorted(changed.items())), logger='current')
        fit_to_cpus(cfg)
        fit_workers(cfg)
        if isinstance(cfg, Config):
            cfg = _FormattedOnce.of(cfg)
        return super().from_cfg(cfg)

    def build_logger(self, *args, **kwargs):
        """mmengine's logger, without the warnings no user can act on
        (:data:`_UNACTIONABLE`)."""
        logger = super().build_logger(*args, **kwargs)
        if not any(isinstance(f, _Unactionable) for f in logger.filters):
            logger.addFilter(_Unactionable())
        return logger

    def train(self):
        """mmengine's, after the cross-field checks of the config against
        the built model (:func:`~wgse_mmseg.utils.cross_checks.
        check_training_fits`: the crop, the batch), before any data is
        read, and with the work dir owned for the whole run
        (:func:`~wgse_mmseg.fileio.locks.own_folder`, job
        ``'train'``: its lock file is ``.lock-train``, so a grid runner
        that owns the folder for its own state can train in it): a second
        training into the same work dir, which would
        interleave its checkpoints and ``last_checkpoint`` with this one's,
        is refused with an :class:`~wgse_mmseg.fileio.output_folder.
        OutputFolderError` naming this process before it writes its config
        or a checkpoint there (only its log, in its own timestamped folder,
        as every run's), or with ``wait_for_work_dir=True`` in the config
        (``tools/train.py --wait``) waits for it. A test or validation run
        of a checkpoint in that work dir is not refused: it writes its own
        timestamped folder."""
        check_training_fits(self.cfg, self.model)
        with self._work_dir_owned():
            super().dump_config()
            return super().train()

    def val(self) -> dict:
        """mmengine's, with the config dumped as it starts."""
        super().dump_config()
        return super().val()

    def test(self) -> dict:
        """mmengine's, with the config dumped as it starts, after the
        checks of the built model against its spikes and classes
        (:func:`~wgse_mmseg.utils.cross_checks.check_model_fits`)."""
        check_model_fits(self.cfg, self.model)
        super().dump_config()
        return super().test()

    def dump_config(self) -> None:
        """Nothing when the runner is built (mmengine dumps the config
        then): :meth:`train`, :meth:`val` and :meth:`test` dump it when
        they start, training once it owns the work dir."""

    @contextlib.contextmanager
    def _work_dir_owned(self):
        """The work dir's lock, taken by the main process for the block;
        every process learns whether it was (a refused distributed run
        stops on every rank, none waits in a collective)."""
        local = osp.isdir(self.work_dir) and is_main_process()
        with contextlib.ExitStack() as owned:
            refusal = [None]
            if local:
                try:
                    owned.enter_context(own_folder(
                        self.work_dir, job='train', claim=False,
                        wait=bool(self.cfg.get('wait_for_work_dir', False))))
                except OutputFolderError as err:
                    refusal = [str(err)]
            broadcast_object_list(refusal)
            if refusal[0] is not None:
                raise OutputFolderError(refusal[0])
            yield

    def load_checkpoint(self, filename: str, *args, **kwargs) -> dict:
        """mmengine's, but a checkpoint with a ``meta['config']`` entry is
        refused (:class:`CheckpointError` naming the file): mmengine's
        :meth:`resume` executes that text (``Config.fromstring``) to compare
        GPU counts, so a checkpoint from elsewhere would run code. mmengine
        itself writes the config under ``meta['cfg']``, which nothing
        executes. A file that weights-only loading refuses (one that pickles
        code) is a :class:`CheckpointError` naming it, on both stacks
        (:mod:`wgse_mmseg.compat.checkpoint_safety`)."""
        # test-time augmentation (tools/test.py --tta) wraps the model: the
        # weights are the wrapped model's, as MMSeg's test tool loads them
        wrapper = self.model if isinstance(self.model, BaseTTAModel) else None
        try:
            if wrapper is not None:
                self.model = wrapper.module
            checkpoint = super().load_checkpoint(filename, *args, **kwargs)
        except SpikeModelMismatchError as err:
            raise SpikeModelMismatchError(f'{filename}: {err}') from None
        except RuntimeError as err:
            if 'size mismatch' not in str(err):
                raise
            raise unfit_weights(filename, self.cfg.get('num_steps'),
                                err) from err
        except pickle.UnpicklingError as err:
            raise CheckpointError(
                f'{filename}: refused: it holds objects that weights-only '
                f'loading does not allow, and a checkpoint is never unpickled '
                f'in full ({load_error(err)})') from err
        finally:
            if wrapper is not None:
                self.model = wrapper
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
        name and renamed over ``filename`` once whole
        (:func:`~wgse_mmseg.fileio.atomic.atomic_path`): a job killed while it
        saves leaves the previous checkpoints and ``last_checkpoint`` (which
        mmengine's checkpoint hook updates after this returns) as they were,
        so ``--resume`` continues from the last complete checkpoint, and the
        next save removes the temporary it left. A save that fails (a full
        disk, a file-size limit) removes its temporary and raises an
        ``OSError`` naming ``filename``'s path. Only the main process
        saves, as in mmengine. ``last_checkpoint``, which mmengine writes
        in place, is never written through a link or into a file with
        other names (:func:`~wgse_mmseg.fileio.output_folder.unshare`)."""
        if not osp.isdir(out_dir):  # a remote backend: as mmengine does it
            return super().save_checkpoint(out_dir, filename, *args,
                                           **kwargs)
        path = osp.join(out_dir, filename)
        for stale in temporaries_of([path]):  # a killed save's, or a link
            discard(stale)
        unshare(osp.join(out_dir, 'last_checkpoint'))
        with atomic_path(path) as temporary:
            super().save_checkpoint(out_dir, osp.relpath(temporary, out_dir),
                                    *args, **kwargs)
