"""Spike-Cityscapes: Cityscapes scenes as spike streams."""
import logging
import os.path as osp
from collections import Counter
from typing import Dict, List

from mmengine.logging import print_log
from mmseg.datasets import CityscapesDataset
from mmseg.registry import DATASETS

from ..argument_checks import check_choice, check_text
from ..fileio.folder_walk import files_under
from ..fileio.markers import sample_problem

__all__ = ['SpikeCityscapesDataset']

_VERIFY_MODES = ('size', 'full', 'none')


@DATASETS.register_module()
class SpikeCityscapesDataset(CityscapesDataset):
    """Spike streams beside Cityscapes' fine labels (19 classes, palette).

    Layout under ``data_root`` (docs/user_guide.md, "Spike-Cityscapes
    layout")::

        spike/{train,val}/<city>/<city>_<seq>_<frame>_spike.spk
        spike/{train,val}/<city>/<city>_<seq>_<frame>_spike.json  marker
        gtFine/{train,val}/<city>/<city>_<seq>_<frame>_gtFine_labelTrainIds.png

    The spike file of an annotated frame ``<name>_leftImg8bit.png`` is
    ``<name>_spike<ext>``; ``img_suffix`` selects the format (``.spk``,
    ``.dat``, ``.npy`` or ``.npz``). Labels are Cityscapes train ids
    (0..18, 255 ignored).

    Complete or absent: the converter and the synthetic dataset write, last,
    a marker ``<name>_spike.json`` recording the size and SHA-256 of the
    spike file and label their run wrote.
    Only samples whose marker matches are served; the others (a run killed
    mid-sample, a re-run with other settings killed after writing one of
    the files) are skipped, and how many and why is logged and kept in
    ``self.skipped`` (reason -> count).

    Args:
        verify: ``'size'`` (default, at start-up: the marker exists, parses,
            and names both files with their sizes), ``'full'`` (also the
            SHA-256 of every file: reads the whole dataset once), or
            ``'none'`` (no marker needed: folders written by other tools).
    """

    def __init__(self,
                 img_suffix: str = '_spike.spk',
                 seg_map_suffix: str = '_gtFine_labelTrainIds.png',
                 verify: str = 'size',
                 **kwargs) -> None:
        entry = 'SpikeCityscapesDataset'
        check_text(entry, 'img_suffix', img_suffix, empty=False)
        check_text(entry, 'seg_map_suffix', seg_map_suffix, empty=False)
        check_choice(entry, 'verify', verify, _VERIFY_MODES)
        self.verify = verify
        self.skipped: Dict[str, int] = {}
        super().__init__(
            img_suffix=img_suffix, seg_map_suffix=seg_map_suffix, **kwargs)

    def load_data_list(self) -> List[dict]:
        """MMSeg's listing of the samples whose marker matches (all of them
        with ``verify='none'``), after a check that names a missing folder;
        an empty listing is an error naming the folder."""
        for key, folder in self.data_prefix.items():
            if folder and not osp.isdir(folder):
                raise FileNotFoundError(
                    f'SpikeCityscapesDataset: {folder} ({key} under '
                    f'data_root={self.data_root!r}) is not a directory; set '
                    f'data_root to a Spike-Cityscapes root (docs/'
                    f'user_guide.md, "Spike-Cityscapes layout") or make one '
                    f'with tools/dataset_converters/spike_cityscapes.py')
        listed = self._listing()
        served, problems = [], Counter()
        for info in listed:
            problem = None if self.verify == 'none' else sample_problem(
                osp.splitext(info['img_path'])[0] + '.json',
                dict(spike=info['img_path'], label=info['seg_map_path']),
                full=self.verify == 'full')
            if problem is None:
                served.append(info)
            else:
                problems[problem] += 1
        self.skipped = dict(problems)
        folder = self.data_prefix.get('img_path', '')
        if problems:
            print_log(
                f'SpikeCityscapesDataset: {folder}: serving {len(served)} '
                f'of {len(listed)} samples; skipped {sum(problems.values())}'
                f' without a matching marker ({self._reasons()}), e.g. left '
                f'by an interrupted conversion; run the converter again to '
                f'complete them', logger='current', level=logging.WARNING)
        if not served:
            raise FileNotFoundError(
                f'SpikeCityscapesDataset: {folder} holds no sample: no '
                f'<name>{self.img_suffix} beside a <name>'
                f'{self.seg_map_suffix} in '
                f'{self.data_prefix.get("seg_map_path", "")}'
                + (f', or none with a matching marker ({self._reasons()}; '
                   f"verify='none' serves folders not written by the "
                   f'converter)' if problems else ''))
        return served

    def _listing(self) -> List[dict]:
        """MMSeg's data list; from a folder (no ``ann_file``), its spike
        files found by :func:`~wgse_mmseg.fileio.folder_walk.files_under`
        (each once, a tree with links to itself walked to its end; MMSeg's
        own listing follows such links forever)."""
        if self.ann_file and not osp.isdir(self.ann_file):
            return super().load_data_list()
        img_dir = self.data_prefix.get('img_path', '')
        ann_dir = self.data_prefix.get('seg_map_path')
        listed = []
        for path in files_under(img_dir, (self.img_suffix, )):
            info = dict(img_path=path, label_map=self.label_map,
                        reduce_zero_label=self.reduce_zero_label,
                        seg_fields=[])
            if ann_dir is not None:
                name = osp.relpath(path, img_dir)[:-len(self.img_suffix)]
                info['seg_map_path'] = osp.join(
                    ann_dir, name + self.seg_map_suffix)
            listed.append(info)
        return listed

    def _reasons(self) -> str:
        return ', '.join(f'{count} {reason}'
                         for reason, count in sorted(self.skipped.items()))
