"""Files: spike files, images and every output the package writes.

Torch-free (NumPy, and OpenCV and Pillow for images), and without
OpenMMLab: the tools, the datasets and the readers use it, the spike maths
(:mod:`wgse_mmseg.core`) does not.

* :mod:`.spike_files` (:mod:`.spike_arrays` for ``.npy``/``.npz``): read
  and write spike streams in every format of
  :mod:`wgse_mmseg.core.spike_formats`;
* :mod:`.images`: image files, bounded before they are decoded;
* :mod:`.atomic`: writes that appear whole or not at all;
* :mod:`.output_folder`, :mod:`.locks`, :mod:`.input_guard`: folders that
  hold only what the package wrote, one writer at a time, and no output
  over an input;
* :mod:`.bounded_reads`: text and JSON files read within stated limits;
* :mod:`.markers`: completion markers of generated samples;
  :mod:`.folder_walk`: the files under a folder, links and loops handled.
"""
from .spike_files import load_spikes, save_spikes, spike_shape

__all__ = ['load_spikes', 'save_spikes', 'spike_shape']
