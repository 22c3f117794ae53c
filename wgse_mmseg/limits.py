"""The stated limits on the work an argument, a config, a checkpoint or a
file can make the package do, in one place (standard library only).

Sizes (``MAX_*``): every size a caller, a config or a checkpoint can ask for
is checked against one of these before anything is allocated
, so that a number typed or crafted into a file cannot ask
for terabytes or a loop that never ends. They are generous for real use: the
largest configs of this repository use ``T = 129``, 512 channels and 3
blocks; a spike camera frame is 250 x 400 (Spike-Cityscapes 1024 x 2048).

Files: whatever a file declares (a header's frame count, a zip member's
inflated size, a YAML document's nesting), the readers check it against the
file and against these limits before they allocate, and an error message
quotes at most :data:`EXCERPT_CHARS` characters of an offending value:

``READ_LIMIT_BYTES``
    the most one spike read may allocate: the requested window as read
    (``length * H * W * itemsize``), and an ``.npz`` member's declared
    inflated size (2 GiB; a 1024x2048 stream of 129 frames is 270 MB).
``TEXT_FILE_LIMIT_BYTES``
    the largest side file, marker or scene file (JSON/YAML) read (1 MiB;
    a converter's marker is a few kB).
``ALLOCATION_LIMIT_BYTES``
    the most one array whose size the user's numbers decide as a product
    (a simulation's ``T x H x W`` spikes) may take, checked as a whole by
    :func:`check_allocation` before it is made: each factor within its own
    limit, the product may not be (8 GiB; a 4096 x 4096 still for 4096
    steps asks for 64 GiB). Raise it with the environment variable
    ``WGSE_MMSEG_ALLOCATION_LIMIT`` (bytes).
``MAX_JSON_DEPTH``
    the deepest nesting of arrays and objects any JSON the package reads
    may have (:func:`wgse_mmseg.fileio.bounded_reads.parse_json`; the
    package writes at most 4 levels), so that no crafted file or metadata can
    exhaust the parser's recursion.
"""
import os

from .errors import EXCERPT_CHARS, cut, excerpt  # noqa: F401

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


#: worker processes or threads of a tool
MAX_WORKERS = 1024


#: samples in one batch a tool builds (a benchmark's ``--batch-size``)
MAX_BATCH_SIZE = 4096


#: training length a tool asks for: epochs, or iterations
MAX_EPOCHS = 100_000


MAX_ITERS = 100_000_000


#: tiles along one side of a figure (its columns of frames)
MAX_FIGURE_TILES = 1024


#: the factor a figure's tiles are resized by
MAX_TILE_SCALE = 64


#: bytes one spike read may allocate (a window, an ``.npz`` member)
READ_LIMIT_BYTES = 2**31


#: bytes one allocation decided by a product of the user's numbers may
#: take, unless ``WGSE_MMSEG_ALLOCATION_LIMIT`` says otherwise
ALLOCATION_LIMIT_BYTES = 2**33


#: the environment variable that raises (or lowers) it, in bytes
ALLOCATION_LIMIT_ENV = 'WGSE_MMSEG_ALLOCATION_LIMIT'


#: bytes of a side file, marker or scene file
TEXT_FILE_LIMIT_BYTES = 2**20


#: bytes of a log or result file of a training run the package reads back
#: (mmengine's logs, an experiment's results)
LOG_FILE_LIMIT_BYTES = 2**28


#: nesting of arrays and objects in JSON read from a file or a model
MAX_JSON_DEPTH = 32


__all__ = []


def allocation_limit() -> int:
    """The allocation limit in bytes: ``WGSE_MMSEG_ALLOCATION_LIMIT`` where
    set (a positive integer, else ``ValueError`` naming it), else
    :data:`ALLOCATION_LIMIT_BYTES`."""
    text = os.environ.get(ALLOCATION_LIMIT_ENV)
    if text is None:
        return ALLOCATION_LIMIT_BYTES
    try:
        limit = int(text.strip())
    except ValueError:
        limit = 0
    if limit < 1:
        raise ValueError(
            f'{ALLOCATION_LIMIT_ENV} must be a positive integer (bytes), '
            f'got {excerpt(text)}')
    return limit


def check_allocation(nbytes: int, what: str, fields: str) -> None:
    """Raise ``ValueError`` before allocating ``nbytes`` bytes for ``what``
    if that is more than :func:`allocation_limit`; ``fields`` names the
    numbers whose product it is, and the message says how to raise the
    limit."""
    limit = allocation_limit()
    if nbytes > limit:
        raise ValueError(
            f'{what} would take {nbytes} bytes ({nbytes / 2**30:.3g} GiB), '
            f'more than the allocation limit of {limit} bytes '
            f'({limit / 2**30:.3g} GiB): lower {fields}, or raise the limit '
            f'with {ALLOCATION_LIMIT_ENV}=<bytes>')
