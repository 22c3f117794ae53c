"""The kinds of the tools' command-line values, as argparse ``type=``.

A tool types every option that takes a value with one of these
(``parser.add_argument('--repeat', type=Integer(1, MAX_REPEAT))``); argparse
then exits with ``argument --repeat: must be an integer >= 1 ..., got
'0'``. A kind reads a word (:meth:`Argument.convert`) and accepts its value
by the rules the library's own checks apply (:mod:`.argument_checks`).
Torch-free, so that every tool's ``--help`` is quick.
"""
import argparse
import copy
from typing import Any, Optional, Sequence

from .argument_checks import (EXPOSURE_CHOICES, LAYOUTS, ArgumentError,
                              integer_expected, is_choice, is_integer,
                              is_number, is_path, number_expected,
                              path_expected)
from .limits import (MAX_CLASSES, MAX_EPOCHS, MAX_IMAGE_SIDE, MAX_ITERS,
                     MAX_NUM_STEPS, MAX_REPEAT, MAX_SEED)
from .errors import excerpt

__all__ = []


class Argument:
    """One kind of command-line value: what it accepts and how that reads.

    Subclasses implement :meth:`accepts` (Python values), :meth:`describe`
    and :meth:`convert` (a word to a Python value). ``optional=True`` also
    accepts ``None`` (a config's value, :mod:`wgse_mmseg.utils.config`).
    """

    def __init__(self, optional: bool = False):
        self.optional = optional

    def accepts(self, value: Any) -> bool:
        raise NotImplementedError

    def or_none(self) -> 'Argument':
        """This kind, also accepting ``None``."""
        other = copy.copy(self)
        other.optional = True
        return other

    def describe(self) -> str:
        raise NotImplementedError

    def expected(self) -> str:
        """:meth:`describe`, with ``or None`` where ``None`` is accepted."""
        return self.describe() + (' or None' if self.optional else '')

    def check(self, value: Any, entry: str, name: str) -> None:
        """Raise :class:`~wgse_mmseg.argument_checks.ArgumentError` unless
        ``value`` is accepted (a config's value, read from text)."""
        if value is None and self.optional:
            return
        if not self.accepts(value):
            raise ArgumentError(entry, name, self.expected(), value)

    def convert(self, text: str) -> Any:
        """The value a command-line word spells (unchecked; may raise)."""
        return text

    def _read(self, text: str) -> Any:
        """:meth:`convert`'s value of ``text`` if accepted, else ``None``."""
        try:
            value = self.convert(text)
        except (TypeError, ValueError, OverflowError):
            return None
        return value if value is not None and self.accepts(value) else None

    def __call__(self, text: str) -> Any:
        """argparse's ``type=``: the checked value of a command-line word."""
        value = self._read(text)
        if value is None:
            raise argparse.ArgumentTypeError(
                f'must be {self.describe()}, got {excerpt(text)}')
        return value

    def __repr__(self):
        return f'{type(self).__name__}({self.expected()})'


class Integer(Argument):
    """An integer in ``[minimum, maximum]``, odd where ``odd=True``
    (:func:`~wgse_mmseg.argument_checks.is_integer`)."""

    def __init__(self, minimum: Optional[int] = None,
                 maximum: Optional[int] = None, odd: bool = False,
                 optional: bool = False):
        super().__init__(optional)
        self.minimum, self.maximum, self.odd = minimum, maximum, odd

    def accepts(self, value):
        return is_integer(value, self.minimum, self.maximum, self.odd)

    def describe(self):
        return integer_expected(self.minimum, self.maximum, self.odd)

    def convert(self, text):
        return int(text)


class Number(Argument):
    """A finite number in ``[minimum, maximum]``, or ``(minimum,
    maximum]`` where ``strict_minimum=True``
    (:func:`~wgse_mmseg.argument_checks.is_number`)."""

    def __init__(self, minimum: Optional[float] = None,
                 maximum: Optional[float] = None,
                 strict_minimum: bool = False, optional: bool = False):
        super().__init__(optional)
        self.minimum, self.maximum = minimum, maximum
        self.strict_minimum = strict_minimum

    def accepts(self, value):
        return is_number(value, self.minimum, self.maximum,
                         self.strict_minimum)

    def describe(self):
        return number_expected(self.minimum, self.maximum,
                               self.strict_minimum)

    def convert(self, text):
        return float(text)


class Flag(Argument):
    """``True`` or ``False``."""

    def accepts(self, value):
        return isinstance(value, bool)

    def describe(self):
        return 'True or False'


class Text(Argument):
    """A string, non-empty where ``empty=False``."""

    def __init__(self, empty: bool = True, optional: bool = False):
        super().__init__(optional)
        self.empty = empty

    def accepts(self, value):
        return isinstance(value, str) and (self.empty or bool(value))

    def describe(self):
        return 'a string' if self.empty else 'a non-empty string'


class Choice(Argument):
    """One of ``choices``, compared with its type (``True`` is not ``1``);
    ``description`` replaces the list in messages (for long lists)."""

    def __init__(self, choices: Sequence, optional: bool = False,
                 description: Optional[str] = None):
        super().__init__(optional)
        self.choices = tuple(choices)
        self.description = description

    def accepts(self, value):
        return is_choice(value, self.choices)

    def describe(self):
        return self.description or f'one of {list(self.choices)}'

    def convert(self, text):
        for choice in self.choices:
            if str(choice) == text:
                return choice
        return None


class Path(Argument):
    """A file system path (non-empty, no NUL); ``exists``: ``'file'`` or
    ``'directory'`` also requires one to be there
    (:func:`~wgse_mmseg.argument_checks.is_path`)."""

    def __init__(self, exists: Optional[str] = None,
                 optional: bool = False):
        super().__init__(optional)
        assert exists in (None, 'file', 'directory')
        self.exists = exists

    def accepts(self, value):
        return is_path(value, self.exists)

    def describe(self):
        return path_expected(self.exists)


class SequenceOf(Argument):
    """A list or tuple of values each accepted by ``item``; on a command
    line, one word of values split at ``separator``.

    Args:
        item: the kind of every value, or with ``names`` one per name
            (``(NUM_STEPS, SIDE, SIDE)`` for ``('T', 'H', 'W')``).
        names: the values' names, fixing the length (``('h', 'w')``).
        ordered: values must not decrease (a ``(low, high)`` range).
        min_length, max_length: bounds on the length without ``names``.
        separator: splits a command-line word into values.
    """

    def __init__(self, item, names: Optional[Sequence] = None,
                 ordered: bool = False, min_length: int = 1,
                 max_length: Optional[int] = None, separator: str = ',',
                 optional: bool = False):
        super().__init__(optional)
        self.item, self.ordered, self.separator = item, ordered, separator
        self.names = tuple(names) if names else None
        if isinstance(item, (list, tuple)):
            assert self.names and len(item) == len(self.names), \
                'one kind per name'
        self.min_length = len(self.names) if self.names else min_length
        self.max_length = len(self.names) if self.names else max_length

    def _items(self, count: int):
        """The kinds of ``count`` values, in order."""
        if isinstance(self.item, (list, tuple)):
            return self.item
        return (self.item,) * count

    def accepts(self, value):
        if not isinstance(value, (list, tuple)):
            return False
        if len(value) < self.min_length or (
                self.max_length is not None and len(value) > self.max_length):
            return False
        if not all(item.accepts(v)
                   for item, v in zip(self._items(len(value)), value)):
            return False
        return not self.ordered or all(a <= b
                                       for a, b in zip(value, value[1:]))

    def describe(self):
        if self.names:
            head = f'({", ".join(self.names)})'
            if self.ordered:
                head += f' with {" <= ".join(self.names)}'
        else:
            count = (f'{self.min_length}+' if self.max_length is None else
                     f'{self.min_length}..{self.max_length}')
            head = f'a sequence of {count} values'
            if self.ordered:
                head += ' in non-decreasing order'
        if isinstance(self.item, (list, tuple)):
            return head + ': ' + ', '.join(
                f'{name} {item.describe()}'
                for name, item in zip(self.names, self.item))
        return f'{head}, each {self.item.describe()}'

    def convert(self, text):
        parts = text.split(self.separator)
        if isinstance(self.item, (list, tuple)) and \
                len(parts) != len(self.item):
            return None
        return tuple(item.convert(part)
                     for item, part in zip(self._items(len(parts)), parts))


class OneOf(Argument):
    """A value that one of ``alternatives`` accepts."""

    def __init__(self, *alternatives: Argument, optional: bool = False):
        super().__init__(optional)
        self.alternatives = alternatives

    def accepts(self, value):
        return any(a.accepts(value) for a in self.alternatives)

    def describe(self):
        return ', or '.join(a.describe() for a in self.alternatives)

    def convert(self, text):
        for alternative in self.alternatives:
            value = alternative._read(text)
            if value is not None:
                return value
        return None


# The kinds many tools share.

#: ``T``, spike frames per window of a recording or a simulated stream
NUM_STEPS = Integer(1, MAX_NUM_STEPS)
#: a frame's height or width
SIDE = Integer(1, MAX_IMAGE_SIDE)
#: ``(h, w)`` of a frame, a crop or a padded batch
FRAME_SIZE = SequenceOf(SIDE, names=('h', 'w'))
#: a seed of a random generator
SEED = Integer(0, MAX_SEED)
#: the epochs of a training run
EPOCHS = Integer(1, MAX_EPOCHS)
#: the iterations of a training run
ITERATIONS = Integer(1, MAX_ITERS)
#: a benchmark's timed calls, and its untimed calls before them
REPEAT = Integer(1, MAX_REPEAT)
WARMUP = Integer(0, MAX_REPEAT)
#: the number of classes of a label map
NUM_CLASSES = Integer(1, MAX_CLASSES)
#: a probability
PROBABILITY = Number(0, 1)
#: the axis order of a 3-D spike array on disk
#: (:data:`~wgse_mmseg.argument_checks.LAYOUTS`)
LAYOUT = Choice(LAYOUTS)
#: a tool's ``--exposure``: ``'auto'``, ``'none'`` or a gain
#: (:func:`wgse_mmseg.core.exposure.apply_exposure`)
EXPOSURE = OneOf(Choice(EXPOSURE_CHOICES), Number(0, strict_minimum=True))
#: the help of a tool's ``--layout`` option
LAYOUT_HELP = ('THW or HWT: how a .npy/.npz that does not record its layout '
               'stores its frames, (T, H, W) or (H, W, T) (default: what the '
               'file records; an error where it records none)')


def add_frame_size_options(parser: argparse.ArgumentParser) -> None:
    """A tool's ``--height`` and ``--width``: the frame size of a ``.dat``
    recording (which records none; :mod:`wgse_mmseg.fileio.spike_files`).
    They go together: :func:`check_frame_size` refuses one without the
    other."""
    parser.add_argument('--height', type=SIDE,
                        help='frame height of a .dat recording (with --width)')
    parser.add_argument('--width', type=SIDE,
                        help='frame width of a .dat recording (with --height)')


def check_frame_size(parser: argparse.ArgumentParser,
                     args: argparse.Namespace) -> None:
    """Exit through ``parser.error`` where ``args`` has one of ``--height``
    and ``--width`` (:func:`add_frame_size_options`) without the other."""
    if (args.height is None) != (args.width is None):
        parser.error('--height and --width go together')
