"""Data generation: spike datasets made from images, without OpenMMLab.

Like :mod:`wgse_mmseg.core`, this package needs no mmengine, mmseg or mmcv
(torch, NumPy, OpenCV and tqdm), so a dataset can be built on any machine:

* :mod:`.cityscapes_conversion`: Cityscapes to Spike-Cityscapes (the
  converter of ``tools/dataset_converters/spike_cityscapes.py``), in shards
  that machines can share (:mod:`.shards`);
* :mod:`.synthetic`: the procedural street-scene dataset in the same layout;
* :mod:`.views`: REDS-style views of still images moved along trajectories;
* :mod:`.training_images`: a folder of the images installed packages ship
  (photographs, video frames), for reconstruction training.

The MMSeg dataset classes that read the results live in
:mod:`wgse_mmseg.datasets`.
"""
