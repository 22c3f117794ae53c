"""The checks a public function makes of its own arguments, in its body.

Each ``check_*`` takes the public entry point's name (what the user called:
``'WGSE'``, ``'load_spikes'``), the parameter's name as the user spells it,
and the value; it returns the value and raises :class:`ArgumentError`,
naming all three with what was expected, where the value does not fit::

    def tfp(spikes, window=5):
        check_integer('tfp', 'window', window, 1)

The ``is_*`` predicates and ``*_expected`` descriptions are the same rules
for the tools' command lines (:mod:`wgse_mmseg.command_line`). Imports only
the standard library and the package's ground floor, so that a tool's
``--help`` needs no torch.
"""
import math
import os
from numbers import Integral, Real
from typing import Any, Optional, Sequence, Tuple

from .limits import MAX_IMAGE_SIDE, MAX_PARAMETERS
from .errors import WgseError, excerpt

__all__ = ['ArgumentError']

#: the magnitudes of a normal float32: a ``float32=True`` number is 0 or
#: one of these, for what enters float32 arithmetic (below, a value is
#: denormal and loses its digits; above, it is Inf)
FLOAT32_RANGE = (2.0 ** -126, (2 - 2.0 ** -23) * 2.0 ** 127)


#: the axis orders of a 3-D spike array on disk: ``'THW'`` (frames first,
#: ``(T, H, W)``) or ``'HWT'`` (frames last, ``(H, W, T)``, as some
#: simulators and viewers store them); see :mod:`wgse_mmseg.fileio.spike_files`
LAYOUTS = ('THW', 'HWT')
#: the exposures of an image from spikes besides a gain: ``'auto'`` and
#: ``'none'`` (see :func:`wgse_mmseg.core.exposure.apply_exposure`)
EXPOSURE_CHOICES = ('auto', 'none')


class ArgumentError(WgseError, ValueError):
    """An argument of a public entry point is not what it takes.

    One ``ValueError`` for a wrong value and a wrong type alike: what is
    expected (``an integer >= 1``) states both, and the caller's mistake is
    the same. Attributes ``entry``, ``argument`` and ``expected`` hold the
    parts of the message.
    """

    def __init__(self, entry: str, argument: str, expected: str, value: Any):
        self.entry = entry
        self.argument = argument
        self.expected = expected
        super().__init__(f'{entry}: {argument} must be {expected}, got '
                         f'{excerpt(value)}')

    def __reduce__(self):
        # picklable with its message as it is, so that it crosses from a
        # worker process (the benchmarks' spawned measurements) intact
        return _rebuilt, (type(self), self.args, self.__dict__)


def _rebuilt(cls, args, state):
    """An :class:`ArgumentError` from its pickled parts."""
    error = Exception.__new__(cls)
    error.args = args
    error.__dict__.update(state)
    return error


def _bound(minimum, maximum, strict_minimum=False) -> str:
    parts = []
    if minimum is not None:
        parts.append(f'{">" if strict_minimum else ">="} {minimum}')
    if maximum is not None:
        parts.append(f'<= {maximum}')
    return ' and '.join(parts)


def integer_expected(minimum: Optional[int] = None,
                     maximum: Optional[int] = None, odd: bool = False) -> str:
    """What :func:`is_integer` accepts, in words."""
    bound = _bound(minimum, maximum)
    return f'{"an odd" if odd else "an"} integer' + (
        f' {bound}' if bound else '')


def is_integer(value: Any, minimum: Optional[int] = None,
               maximum: Optional[int] = None, odd: bool = False) -> bool:
    """An ``int`` or NumPy integer (not ``bool``) in ``[minimum,
    maximum]``, odd where ``odd``."""
    return (isinstance(value, Integral) and not isinstance(value, bool)
            and (minimum is None or value >= minimum)
            and (maximum is None or value <= maximum)
            and (not odd or value % 2 == 1))


def check_integer(entry: str, name: str, value: Any,
                  minimum: Optional[int] = None,
                  maximum: Optional[int] = None, *, odd: bool = False,
                  optional: bool = False) -> Any:
    """``value``, an integer as :func:`is_integer` says (or ``None`` where
    ``optional``)."""
    if not (optional and value is None) and \
            not is_integer(value, minimum, maximum, odd):
        raise ArgumentError(entry, name, integer_expected(
            minimum, maximum, odd) + (' or None' if optional else ''), value)
    return value


def number_expected(minimum: Optional[float] = None,
                    maximum: Optional[float] = None,
                    strict_minimum: bool = False,
                    float32: bool = False) -> str:
    """What :func:`is_number` accepts, in words."""
    bound = _bound(minimum, maximum, strict_minimum)
    return 'a finite number' + (f' {bound}' if bound else '') + (
        f" in float32's normal range (0 or a magnitude in "
        f'[{FLOAT32_RANGE[0]:.4g}, {FLOAT32_RANGE[1]:.4g}])'
        if float32 else '')


def is_number(value: Any, minimum: Optional[float] = None,
              maximum: Optional[float] = None, strict_minimum: bool = False,
              float32: bool = False) -> bool:
    """A finite real number (not ``bool``) in ``[minimum, maximum]``
    (``(minimum, maximum]`` where ``strict_minimum``); with ``float32``,
    also 0 or a normal float32 (a magnitude in :data:`FLOAT32_RANGE`)."""
    if isinstance(value, bool) or not isinstance(value, Real) or \
            not math.isfinite(value):
        return False
    if float32 and value != 0 and not (
            FLOAT32_RANGE[0] <= abs(value) <= FLOAT32_RANGE[1]):
        return False
    if minimum is not None and (value < minimum or
                                (strict_minimum and value == minimum)):
        return False
    return maximum is None or value <= maximum


def check_number(entry: str, name: str, value: Any,
                 minimum: Optional[float] = None,
                 maximum: Optional[float] = None, *,
                 strict_minimum: bool = False, float32: bool = False,
                 optional: bool = False) -> Any:
    """``value``, a number as :func:`is_number` says (or ``None`` where
    ``optional``)."""
    if not (optional and value is None) and not is_number(
            value, minimum, maximum, strict_minimum, float32):
        raise ArgumentError(entry, name, number_expected(
            minimum, maximum, strict_minimum, float32) + (
                ' or None' if optional else ''), value)
    return value


def is_choice(value: Any, choices: Sequence) -> bool:
    """One of ``choices``, compared with its type (``True`` is not
    ``1``)."""
    return any(type(value) is type(choice) and value == choice
               for choice in choices)


def check_choice(entry: str, name: str, value: Any, choices: Sequence, *,
                 optional: bool = False,
                 description: Optional[str] = None) -> Any:
    """``value``, one of ``choices`` (:func:`is_choice`; or ``None`` where
    ``optional``); ``description`` replaces the list in the message (for
    long lists)."""
    if not (optional and value is None) and not is_choice(value, choices):
        raise ArgumentError(entry, name, (
            description or f'one of {list(choices)}') + (
                ' or None' if optional else ''), value)
    return value


def check_flag(entry: str, name: str, value: Any) -> bool:
    """``value``, ``True`` or ``False``."""
    if not isinstance(value, bool):
        raise ArgumentError(entry, name, 'True or False', value)
    return value


def check_text(entry: str, name: str, value: Any, *, empty: bool = True,
               optional: bool = False) -> Any:
    """``value``, a string (non-empty unless ``empty``; or ``None`` where
    ``optional``)."""
    if not (optional and value is None) and not (
            isinstance(value, str) and (empty or value)):
        raise ArgumentError(entry, name, ('a string' if empty else
                                          'a non-empty string') +
                            (' or None' if optional else ''), value)
    return value


def path_expected(exists: Optional[str] = None) -> str:
    """What :func:`is_path` accepts, in words."""
    return 'a path' + (f' to an existing {exists}' if exists else '')


def is_path(value: Any, exists: Optional[str] = None) -> bool:
    """A file system path (``str`` or ``os.PathLike``, non-empty, no NUL);
    ``exists``: ``'file'`` or ``'directory'`` also wants one there."""
    if not isinstance(value, (str, os.PathLike)):
        return False
    text = os.fspath(value)
    if not isinstance(text, str) or not text or '\0' in text:
        return False
    if exists == 'file':
        return os.path.isfile(text)
    return exists != 'directory' or os.path.isdir(text)


def check_path(entry: str, name: str, value: Any, *,
               exists: Optional[str] = None, optional: bool = False) -> Any:
    """``value``, a path as :func:`is_path` says (or ``None`` where
    ``optional``). Readers check their files themselves, naming them."""
    if not (optional and value is None) and not is_path(value, exists):
        raise ArgumentError(entry, name, path_expected(exists) + (
            ' or None' if optional else ''), value)
    return value


def check_frame_size(entry: str, name: str, value: Any, *,
                     side: bool = False) -> Tuple[int, int]:
    """``(h, w)`` of a frame, a crop or a padded batch: a pair of integers
    in ``[1, MAX_IMAGE_SIDE]``; with ``side``, also one integer for both
    (returned as a pair)."""
    if side and is_integer(value, 1, MAX_IMAGE_SIDE):
        return value, value
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and
            all(is_integer(v, 1, MAX_IMAGE_SIDE) for v in value)):
        pair = f'(h, w), each {integer_expected(1, MAX_IMAGE_SIDE)}'
        raise ArgumentError(entry, name, pair + (
            f', or {integer_expected(1, MAX_IMAGE_SIDE)}' if side else ''),
            value)
    return tuple(value)


def check_layout(entry: str, layout: Any) -> Optional[str]:
    """``layout``, one of :data:`LAYOUTS` or ``None`` (what the file
    records), as every reader of a recording takes it."""
    return check_choice(entry, 'layout', layout, LAYOUTS, optional=True)


def check_read_options(entry: str, height: Any, width: Any,
                       layout: Any) -> None:
    """The options every reader of a recording takes: the frame ``height``
    and ``width`` (a ``.dat`` file's; each at most
    :data:`~wgse_mmseg.limits.MAX_IMAGE_SIDE`) and the ``layout``
    (:func:`check_layout`), each ``None`` for what the file records."""
    for name, side in (('height', height), ('width', width)):
        check_integer(entry, name, side, 1, MAX_IMAGE_SIDE, optional=True)
    check_layout(entry, layout)


def check_parameter_count(entry: str, count: int, fields: str) -> None:
    """Refuse a learned module of more than
    :data:`~wgse_mmseg.limits.MAX_PARAMETERS` parameters before
    building it; ``fields`` names the arguments that set the count."""
    if count > MAX_PARAMETERS:
        raise ArgumentError(
            entry, fields, f'small enough for at most {MAX_PARAMETERS} '
            f'parameters (MAX_PARAMETERS)', count)
