"""Spike-Cityscapes: Cityscapes scenes as spike streams."""
import os.path as osp
from typing import List

from mmseg.datasets import CityscapesDataset
from mmseg.registry import DATASETS

__all__ = ['SpikeCityscapesDataset']


@DATASETS.register_module()
class SpikeCityscapesDataset(CityscapesDataset):
    """Spike streams beside Cityscapes' fine labels (19 classes, palette).

    Layout under ``data_root`` (README, "Spike-Cityscapes")::

        spike/{train,val}/<city>/<city>_<seq>_<frame>_spike.spk
        gtFine/{train,val}/<city>/<city>_<seq>_<frame>_gtFine_labelTrainIds.png

    The spike file of an annotated frame ``<name>_leftImg8bit.png`` is
    ``<name>_spike<ext>``; ``img_suffix`` selects the format (``.spk``,
    ``.dat``, ``.npy`` or ``.npz``). Labels are Cityscapes train ids
    (0..18, 255 ignored).
    """

    def __init__(self,
                 img_suffix: str = '_spike.spk',
                 seg_map_suffix: str = '_gtFine_labelTrainIds.png',
                 **kwargs) -> None:
        super().__init__(
            img_suffix=img_suffix, seg_map_suffix=seg_map_suffix, **kwargs)

    def load_data_list(self) -> List[dict]:
        """MMSeg's listing, after a check that names a missing folder."""
        for key, folder in self.data_prefix.items():
            if folder and not osp.isdir(folder):
                raise FileNotFoundError(
                    f'SpikeCityscapesDataset: {folder} ({key} under '
                    f'data_root={self.data_root!r}) is not a directory; set '
                    f'data_root to a Spike-Cityscapes root (README, '
                    f'"Spike-Cityscapes layout") or make one with '
                    f'tools/dataset_converters/spike_cityscapes.py')
        return super().load_data_list()
