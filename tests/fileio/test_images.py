"""Every image kind keeps its meaning (issue 32, item 3): bool, 8-bit,
16-bit and float images, as arrays given to the quality measures and as
files read by the image readers, are scored/read on one scale or refused;
and each measure keeps its stated memory bound.

The 2-D entropy is checked against a straightforward reference (a float
3x3 mean of the symmetrically padded image, ``np.unique`` of the pairs).
"""
import importlib
import tracemalloc

import cv2
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from skimage import data as skimage_data

from wgse_mmseg.core.image_values import as_grey_levels, as_unit_grey
from wgse_mmseg.fileio.images import read_grey_image
from wgse_mmseg.evaluation.quality import brisque, entropy_2d, niqe
from wgse_mmseg.evaluation.quality.no_reference import no_reference_scores


#: the modules (their names are shadowed by the functions in the package)
niqe_module, brisque_module = (importlib.import_module(
    f'wgse_mmseg.evaluation.quality.{name}') for name in ('niqe', 'brisque'))


def _reference_entropy(levels):
    """2-D entropy of 8-bit ``levels`` by its definition."""
    grey = levels.astype(np.float64)
    padded = np.pad(grey, 1, mode='symmetric')
    height, width = grey.shape
    total = sum(padded[dy:dy + height, dx:dx + width]
                for dy in range(3) for dx in range(3))
    mean = np.floor(total / 9 + 0.5)  # never halfway: 9 is odd
    _, counts = np.unique(np.stack([grey, mean]).reshape(2, -1), axis=1,
                          return_counts=True)
    p = counts / counts.sum()
    return float(-(p * np.log2(p)).sum())


@settings(max_examples=150, deadline=None)
@given(height=st.integers(1, 12), width=st.integers(1, 12),
       seed=st.integers(0, 2**32 - 1), levels=st.integers(1, 256))
def test_entropy_matches_its_definition(height, width, seed, levels):
    rng = np.random.default_rng(seed)
    image = rng.integers(0, levels, (height, width)).astype(np.uint8)
    expected = _reference_entropy(image)
    assert np.isclose(entropy_2d(image), expected, rtol=0, atol=1e-12)
    # the same picture as 16 bits, as float, and (two levels) as bool
    assert np.isclose(entropy_2d(image.astype(np.uint16) * 257), expected)
    assert np.isclose(entropy_2d(image / 255.0), expected)
    binary = image > levels // 2
    assert np.isclose(entropy_2d(binary),
                      _reference_entropy(binary.astype(np.uint8) * 255))


def test_entropy_past_8192_pixels_a_side():
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, (3, 40_000)).astype(np.uint8)
    assert np.isclose(entropy_2d(image), _reference_entropy(image))
    assert np.isclose(entropy_2d(image.T), _reference_entropy(image.T))


def test_sixteen_bit_images_are_not_saturated():
    """The issue's case: a 16-bit photograph scores as its 8-bit self (not
    as white), in every measure."""
    image = skimage_data.camera()
    wide = image.astype(np.uint16) * 257
    assert entropy_2d(wide) == entropy_2d(image) > 7
    assert niqe(wide) == niqe(image)
    assert brisque(wide) == brisque(image)
    assert no_reference_scores(wide) == no_reference_scores(image)


@pytest.mark.parametrize('image, words', [
    (np.full((20, 20), 1.5), 'must lie in \\[0, 1\\].*found values in '
     '\\[1.5, 1.5\\]'),
    (np.full((20, 20), -0.25), 'found values in \\[-0.25'),
    (np.arange(400, dtype=np.int64).reshape(20, 20), 'dtype int64'),
    (np.zeros((20, 20), np.int16), 'dtype int16'),
    (np.zeros((20, 20), np.uint32), 'dtype uint32'),
    (np.zeros((20, 20), np.complex64), 'dtype complex64'),
    (np.full((20, 20), np.inf), 'non-finite'),
])
def test_images_of_unknown_meaning_are_refused(image, words):
    for measure in (niqe, brisque, entropy_2d, no_reference_scores,
                    as_unit_grey, as_grey_levels):
        with pytest.raises(ValueError, match='image.*' + words):
            measure(image)


def test_bool_and_uint8_keep_their_scale():
    image = np.array([[False, True], [True, False]])
    assert (as_unit_grey(image) == image).all()
    assert (as_grey_levels(image) == image * 255).all()
    levels = np.arange(256, dtype=np.uint8).reshape(16, 16)
    assert (as_grey_levels(levels.astype(np.uint16) * 257) == levels).all()
    assert (as_grey_levels(levels / 255.0) == levels).all()


@pytest.mark.parametrize('measure, bound, side', [
    (entropy_2d, 2.5, 2048), (niqe, niqe_module.BYTES_PER_PIXEL, 768),
    (brisque, brisque_module.BYTES_PER_PIXEL, 768)])
def test_measures_keep_their_memory_bound(measure, bound, side):
    """Peak bytes allocated per pixel, for a float32 image (converted to
    8 bits inside); entropy needs 2.5 at most, the others what they
    state."""
    rng = np.random.default_rng(0)
    image = cv2.GaussianBlur(rng.random((side, side)), (0, 0), 1.0).astype(
        np.float32)
    measure(image[:200, :200])  # caches and lazy imports, not per pixel
    tracemalloc.start()
    try:
        measure(image)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak / image.size <= bound


def test_image_files_keep_their_depth(tmp_path):
    rng = np.random.default_rng(2)
    wide = rng.integers(0, 65536, (9, 11)).astype(np.uint16)
    cv2.imwrite(str(tmp_path / 'wide.png'), wide)
    assert np.allclose(read_grey_image(str(tmp_path / 'wide.png')),
                       wide / 65535.0, atol=1e-7)
    narrow = rng.integers(0, 256, (9, 11)).astype(np.uint8)
    cv2.imwrite(str(tmp_path / 'narrow.png'), narrow)
    assert np.allclose(read_grey_image(str(tmp_path / 'narrow.png')),
                       narrow / 255.0, atol=1e-7)
    colour = rng.integers(0, 65536, (9, 11, 4)).astype(np.uint16)
    cv2.imwrite(str(tmp_path / 'colour.png'), colour)  # BGRA, 16 bits
    luma = cv2.cvtColor(colour[..., :3], cv2.COLOR_BGR2GRAY) / 65535.0
    assert np.allclose(read_grey_image(str(tmp_path / 'colour.png')), luma,
                       atol=1e-7)
    unit = rng.random((9, 11)).astype(np.float32)
    cv2.imwrite(str(tmp_path / 'unit.tiff'), unit)
    assert np.array_equal(read_grey_image(str(tmp_path / 'unit.tiff')), unit)
    cv2.imwrite(str(tmp_path / 'hdr.tiff'), unit * 4)
    with pytest.raises(ValueError, match='hdr.tiff: a float image must lie '
                       'in \\[0, 1\\]'):
        read_grey_image(str(tmp_path / 'hdr.tiff'))
    with pytest.raises(FileNotFoundError, match='none.png'):
        read_grey_image(str(tmp_path / 'none.png'))


def test_the_simulator_reads_frames_of_every_kind_on_one_scale():
    """frames_to_intensity follows the same rules: 16-bit and bool frames
    are intensities in [0, 1], not 257 or 65535 times too bright."""
    from wgse_mmseg.core.simulation.intensity import frames_to_intensity
    rng = np.random.default_rng(3)
    frames = rng.integers(0, 256, (2, 5, 6, 3)).astype(np.uint8)
    expected = frames_to_intensity(frames)
    assert np.allclose(frames_to_intensity(frames.astype(np.uint16) * 257),
                       expected, rtol=0, atol=1e-12)
    assert np.allclose(frames_to_intensity(frames / 255.0), expected)
    binary = frames[..., 0] > 127
    assert np.array_equal(frames_to_intensity(binary).numpy(), binary)
    with pytest.raises(ValueError, match='frames must be a bool, uint8'):
        frames_to_intensity(frames.astype(np.int32))


# ------------------------------------------- image files bounded before decode
from wgse_mmseg.core.image_values import fit_within  # noqa: E402
from wgse_mmseg.fileio.images import (ImageFileError, image_size,  # noqa: E402
                                      read_image)
from wgse_mmseg.limits import MAX_IMAGE_SIDE  # noqa: E402

#: every kind image_size reads, as OpenCV writes it
KINDS = {'.png': 'png', '.jpg': 'jpeg', '.bmp': 'bmp', '.tiff': 'tiff',
         '.webp': 'webp', '.pgm': 'pnm'}


@settings(max_examples=40, deadline=None)
@given(height=st.integers(1, 300), width=st.integers(1, 300),
       ext=st.sampled_from(sorted(KINDS)), colour=st.booleans())
def test_the_header_gives_the_size_opencv_decodes(tmp_path_factory, height,
                                                  width, ext, colour):
    if ext == '.pgm' and colour:
        ext = '.ppm'
    path = str(tmp_path_factory.mktemp('size') / f'i{ext}')
    shape = (height, width, 3) if colour else (height, width)
    cv2.imwrite(path, np.random.default_rng(0).integers(0, 256, shape,
                                                        np.uint8))
    kind, got_width, got_height = image_size(path)
    assert kind == KINDS.get(ext, 'pnm')
    assert (got_height, got_width) == read_image(path).shape[:2] == shape[:2]


def _png_header(width, height):
    """A PNG's signature, IHDR chunk declaring ``width`` x ``height``
    (8-bit grey) and the head of an empty IDAT chunk: what a decoder reads
    before the pixels."""
    import struct
    import zlib
    body = b'IHDR' + struct.pack('>IIBBBBB', width, height, 8, 0, 0, 0, 0)
    return (b'\x89PNG\r\n\x1a\n' + struct.pack('>I', 13) + body +
            struct.pack('>I', zlib.crc32(body)) + struct.pack('>I', 0) +
            b'IDAT' + struct.pack('>I', zlib.crc32(b'IDAT')))


@pytest.mark.parametrize('width, height', [(60000, 60000), (17000, 17000),
                                           (MAX_IMAGE_SIDE + 1, 1), (0, 5)])
def test_a_header_beyond_the_limits_is_refused_before_decoding(
        tmp_path, width, height):
    path = tmp_path / 'big.png'
    path.write_bytes(_png_header(width, height) + b'\0' * 64)
    with pytest.raises(ImageFileError, match='big.png: (its header declares|'
                       'not an image file)'):
        read_image(str(path))
    with pytest.raises(ValueError, match='big.png'):
        read_grey_image(str(path))


@pytest.mark.parametrize('ext', ['.png', '.jpg'])
def test_a_truncated_image_is_refused(tmp_path, ext):
    path = tmp_path / f'cut{ext}'
    image = np.random.default_rng(1).integers(0, 256, (64, 64), np.uint8)
    cv2.imwrite(str(path), image)
    whole = path.read_bytes()
    path.write_bytes(whole[:len(whole) * 2 // 3])
    with pytest.raises(ImageFileError, match=f'cut{ext}: a truncated'):
        read_image(str(path))


def test_other_files_are_refused_naming_them(tmp_path):
    import os
    (tmp_path / 'notes.png').write_text('not an image')
    with pytest.raises(ImageFileError, match='notes.png: not an image file'):
        read_image(str(tmp_path / 'notes.png'))
    os.mkfifo(tmp_path / 'pipe.png')
    with pytest.raises(ImageFileError, match='pipe.png: not a regular file'):
        read_image(str(tmp_path / 'pipe.png'))
    with pytest.raises(FileNotFoundError, match='gone.png'):
        read_image(str(tmp_path / 'gone.png'))


@pytest.mark.parametrize('shape, bound, want', [
    ((1, 100000), 64, (1, 64)), ((100000, 1), 64, (64, 1)),
    ((30, 40), 64, (30, 40)), ((640, 480), 64, (64, 48)),
    ((3, 1000, 3), 10, (1, 10, 3))])
def test_fit_within_never_makes_a_side_of_zero(shape, bound, want):
    image = np.zeros(shape, np.float32)
    assert fit_within(image, bound).shape == want


def test_a_path_that_is_not_utf8_is_named_as_such(tmp_path):
    """OpenCV's reader crashed the process on such a path; it is refused
    first, the path shown escaped."""
    import os
    path = os.path.join(os.fsencode(str(tmp_path)), b'frame\xff.png')
    cv2.imwrite(str(tmp_path / 'ok.png'), np.zeros((4, 4), np.uint8))
    os.replace(str(tmp_path / 'ok.png'), path)
    with pytest.raises(ValueError, match=r"frame\\udcff\.png': the path "
                       'holds bytes that are not UTF-8, which OpenCV cannot '
                       'open'):
        read_image(os.fsdecode(path))


def test_an_image_is_bounded_as_a_whole_before_decoding(
        tmp_path, monkeypatch):
    import cv2
    from wgse_mmseg.fileio.images import read_image
    from wgse_mmseg.limits import ALLOCATION_LIMIT_ENV
    path = str(tmp_path / 'wide.png')
    cv2.imwrite(path, np.zeros((40, 300), np.uint8))
    assert read_image(path).shape == (40, 300)
    monkeypatch.setenv(ALLOCATION_LIMIT_ENV, str(40 * 300 * 8 - 1))
    with pytest.raises(ValueError, match=r'wide.png: decoding its 300x40 '
                       r'image would take 96000 bytes.*WGSE_MMSEG_'
                       r'ALLOCATION_LIMIT'):
        read_image(path)
