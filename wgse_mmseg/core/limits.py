"""The stated upper limits on sizes, in one place.

Every size a caller, a config or a checkpoint can ask for is checked against
one of these before anything is allocated (:mod:`.arguments`), so that a
number typed or crafted into a file cannot ask for terabytes or a loop that
never ends. They are generous for real use: the largest configs of this
repository use ``T = 129``, 512 channels and 3 blocks; a spike camera frame
is 250 x 400 (Spike-Cityscapes 1024 x 2048).
"""

#: ``T``: spike frames per window (``num_steps``) a model, transform,
#: converter or the simulator works on (0.2 s of a 20 kHz camera)
MAX_NUM_STEPS = 4096
#: height, width, crop and padded size of a frame, in pixels
MAX_IMAGE_SIDE = 16384
#: width of a learned network (``hidden_channels``, ``channels``,
#: ``mid_channels``)
MAX_CHANNELS = 1024
#: residual blocks of a learned network (``num_blocks``)
MAX_NUM_BLOCKS = 16
#: DWT levels of WGSE (``level``): 5 in the paper; past ``log2(T)`` levels
#: the bands of a ``T <= MAX_NUM_STEPS`` stream stop shrinking
MAX_LEVEL = 16
#: side of a learned convolution kernel (``kernel_size``)
MAX_KERNEL_SIZE = 31
#: window of a parameter-free filter (TFP ``window``, mean filters'
#: ``kernel_size``)
MAX_WINDOW = 2 * MAX_NUM_STEPS - 1
#: parameters of one learned module built from arguments, a config or a
#: checkpoint (200 MB of float32; WGSE has about 0.1 million, the
#: reconstruction head at its paper width about 3.5 million)
MAX_PARAMETERS = 50_000_000
#: samples or scenes one dataset or converter run may declare
MAX_SAMPLES = 1_000_000
#: classes of a segmentation label map (uint8 labels, 255 is ignored)
MAX_CLASSES = 255
#: seeds are 63-bit non-negative integers (NumPy and torch accept them)
MAX_SEED = 2**63 - 1
#: repetitions of a benchmark measurement
MAX_REPEAT = 100_000
#: worker processes of a tool
MAX_WORKERS = 1024

__all__ = [name for name in dir() if name.startswith('MAX_')]
