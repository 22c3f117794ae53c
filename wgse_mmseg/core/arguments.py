"""Argument checks, declared once per public entry point.

A public entry point (the constructor of a registered class, a reader, the
simulator, a converter) declares each argument's kind, range and stated
limit (:mod:`.limits`) with :func:`declare`::

    @declare(level=Integer(1, MAX_LEVEL), mode=Choice(SUPPORTED_MODES))
    def __init__(self, level=5, mode='zero'): ...

Every call then checks the bound arguments before the body runs (so before
anything is allocated) and raises :class:`ArgumentError`, naming the entry
point, the argument, what was expected and a bounded excerpt of what came.
The checked function keeps its :class:`Declaration` in its ``declaration``
attribute (a class's in ``__init__.declaration``), for tools that reuse a
declared kind on their command line and for tests that enumerate them.

A tool's command line uses the same kinds as argparse ``type=`` functions
(``parser.add_argument('--repeat', type=Integer(1, MAX_REPEAT))``): argparse
then exits with ``argument --repeat: must be an integer >= 1 ...``.
"""
import argparse
import copy
import functools
import inspect
import math
import os
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, Callable, Dict, Optional, Sequence

from ..errors import excerpt
from ..limits import (MAX_CLASSES, MAX_EPOCHS, MAX_IMAGE_SIDE, MAX_ITERS,
                      MAX_NUM_STEPS, MAX_PARAMETERS, MAX_SEED)

__all__ = ['ArgumentError']


class ArgumentError(ValueError):
    """An argument is not what its entry point declares.

    One ``ValueError`` for a wrong value and a wrong type alike: a declared
    kind (``an integer >= 1``) states both, and the caller's mistake is the
    same. Attributes ``entry``, ``argument`` and ``expected`` hold the parts
    of the message.
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


class Argument:
    """One declared argument: what it accepts and how that reads.

    Subclasses implement :meth:`accepts` (Python values), :meth:`describe`
    and, for command lines, :meth:`convert` (text to a Python value).
    ``optional=True`` also accepts ``None``.
    """

    def __init__(self, optional: bool = False):
        self.optional = optional

    def accepts(self, value: Any) -> bool:
        raise NotImplementedError

    def or_none(self) -> 'Argument':
        """This declaration, also accepting ``None``."""
        other = copy.copy(self)
        other.optional = True
        return other

    def describe(self) -> str:
        raise NotImplementedError

    def expected(self) -> str:
        """:meth:`describe`, with ``or None`` where ``None`` is accepted."""
        return self.describe() + (' or None' if self.optional else '')

    def check(self, value: Any, entry: str, name: str) -> None:
        """Raise :class:`ArgumentError` unless ``value`` is accepted."""
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


def _bound(minimum, maximum, strict_minimum=False) -> str:
    parts = []
    if minimum is not None:
        parts.append(f'{">" if strict_minimum else ">="} {minimum}')
    if maximum is not None:
        parts.append(f'<= {maximum}')
    return ' and '.join(parts)


class Integer(Argument):
    """An ``int`` or NumPy integer (not ``bool``) in ``[minimum, maximum]``,
    odd where ``odd=True``."""

    def __init__(self, minimum: Optional[int] = None,
                 maximum: Optional[int] = None, odd: bool = False,
                 optional: bool = False):
        super().__init__(optional)
        self.minimum, self.maximum, self.odd = minimum, maximum, odd

    def accepts(self, value):
        return (isinstance(value, Integral) and not isinstance(value, bool)
                and (self.minimum is None or value >= self.minimum)
                and (self.maximum is None or value <= self.maximum)
                and (not self.odd or value % 2 == 1))

    def describe(self):
        bound = _bound(self.minimum, self.maximum)
        return f'{"an odd" if self.odd else "an"} integer' + (
            f' {bound}' if bound else '')

    def convert(self, text):
        return int(text)


#: the magnitudes of a normal float32: ``Number(float32=True)`` accepts 0
#: and these, for what enters float32 arithmetic (below, a value is
#: denormal and loses its digits; above, it is Inf)
FLOAT32_RANGE = (2.0 ** -126, (2 - 2.0 ** -23) * 2.0 ** 127)


class Number(Argument):
    """A finite real number (not ``bool``) in ``[minimum, maximum]``, or
    ``(minimum, maximum]`` where ``strict_minimum=True``; with
    ``float32=True``, also 0 or a normal float32 (magnitude in
    :data:`FLOAT32_RANGE`)."""

    def __init__(self, minimum: Optional[float] = None,
                 maximum: Optional[float] = None,
                 strict_minimum: bool = False, optional: bool = False,
                 float32: bool = False):
        super().__init__(optional)
        self.minimum, self.maximum = minimum, maximum
        self.strict_minimum = strict_minimum
        self.float32 = float32

    def accepts(self, value):
        if isinstance(value, bool) or not isinstance(value, Real) or \
                not math.isfinite(value):
            return False
        if self.float32 and value != 0 and not (
                FLOAT32_RANGE[0] <= abs(value) <= FLOAT32_RANGE[1]):
            return False
        if self.minimum is not None and (
                value < self.minimum or
                (self.strict_minimum and value == self.minimum)):
            return False
        return self.maximum is None or value <= self.maximum

    def describe(self):
        bound = _bound(self.minimum, self.maximum, self.strict_minimum)
        return 'a finite number' + (f' {bound}' if bound else '') + (
            f" in float32's normal range (0 or a magnitude in "
            f'[{FLOAT32_RANGE[0]:.4g}, {FLOAT32_RANGE[1]:.4g}])'
            if self.float32 else '')

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
        return any(type(value) is type(choice) and value == choice
                   for choice in self.choices)

    def describe(self):
        return self.description or f'one of {list(self.choices)}'

    def convert(self, text):
        for choice in self.choices:
            if str(choice) == text:
                return choice
        return None


class Path(Argument):
    """A file system path (``str`` or ``os.PathLike``, non-empty, no NUL).

    ``exists``: ``'file'`` or ``'directory'`` also requires one to be there
    (readers check their files themselves, naming the file).
    """

    def __init__(self, exists: Optional[str] = None,
                 optional: bool = False):
        super().__init__(optional)
        assert exists in (None, 'file', 'directory')
        self.exists = exists

    def accepts(self, value):
        if not isinstance(value, (str, os.PathLike)):
            return False
        text = os.fspath(value)
        if not isinstance(text, str) or not text or '\0' in text:
            return False
        if self.exists == 'file':
            return os.path.isfile(text)
        return self.exists != 'directory' or os.path.isdir(text)

    def describe(self):
        return 'a path' + (f' to an existing {self.exists}'
                           if self.exists else '')


class SequenceOf(Argument):
    """A list or tuple of values each accepted by ``item``.

    Args:
        item: the declaration of every value, or with ``names`` one per
            name (``(NUM_STEPS, SIDE, SIDE)`` for ``('T', 'H', 'W')``).
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
                'one declaration per name'
        self.min_length = len(self.names) if self.names else min_length
        self.max_length = len(self.names) if self.names else max_length

    def _items(self, count: int):
        """The declarations of ``count`` values, in order."""
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


@dataclass
class Declaration:
    """The declared arguments of one entry point.

    Attributes:
        entry: the name errors give (a class name for a constructor).
        function: the checked function (a constructor's ``__init__``).
        arguments: argument name -> :class:`Argument`.
    """
    entry: str
    function: Callable
    arguments: Dict[str, Argument]

    def check(self, values: Dict[str, Any]) -> None:
        """Check the declared ones of ``values`` (name -> value)."""
        for name, argument in self.arguments.items():
            if name in values:
                argument.check(values[name], self.entry, name)


def declare(**arguments: Argument) -> Callable[[Callable], Callable]:
    """Declare ``arguments`` of a function or of a constructor
    (``__init__``); the returned function checks them on every call before
    its body runs (defaults included)."""

    def wrap(function: Callable) -> Callable:
        signature = inspect.signature(function)
        unknown = set(arguments) - set(signature.parameters)
        if unknown:
            raise TypeError(f'{function.__qualname__} declares '
                            f'{sorted(unknown)}, which it does not take')
        qualname = function.__qualname__
        entry = (qualname[:-len('.__init__')]
                 if qualname.endswith('.__init__') else function.__name__)
        declaration = Declaration(entry, function, dict(arguments))

        @functools.wraps(function)
        def checked(*args, **kwargs):
            try:
                bound = signature.bind(*args, **kwargs)
            except TypeError as err:
                raise TypeError(f'{entry}: {err}') from None
            bound.apply_defaults()
            declaration.check(bound.arguments)
            return function(*args, **kwargs)

        checked.declaration = declaration
        return checked

    return wrap


def declare_fields(**arguments: Argument) -> Callable[[type], type]:
    """:func:`declare` for the constructor of a dataclass (put it above
    ``@dataclass``)."""

    def wrap(cls: type) -> type:
        cls.__init__ = declare(**arguments)(cls.__init__)
        return cls

    return wrap


def check_parameter_count(entry: str, count: int, fields: str) -> None:
    """Refuse a learned module of more than :data:`~.limits.MAX_PARAMETERS`
    parameters before building it; ``fields`` names the arguments that set
    the count (each within its own limit, their product may not be)."""
    if count > MAX_PARAMETERS:
        raise ArgumentError(
            entry, fields, f'small enough for at most {MAX_PARAMETERS} '
            f'parameters (MAX_PARAMETERS)', count)


# The declarations many entry points share.

#: ``T``, spike frames per window
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
#: the number of classes of a label map
NUM_CLASSES = Integer(1, MAX_CLASSES)
#: a probability
PROBABILITY = Number(0, 1)
#: the axis order of a 3-D spike array on disk: ``'THW'`` (frames first,
#: ``(T, H, W)``) or ``'HWT'`` (frames last, ``(H, W, T)``, as some
#: simulators and viewers store them); see :mod:`.io`
LAYOUT = Choice(('THW', 'HWT'))
#: the help of a tool's ``--layout`` option
LAYOUT_HELP = ('THW or HWT: how a .npy/.npz that does not record its layout '
               'stores its frames, (T, H, W) or (H, W, T) (default: what the '
               'file records; an error where it records none)')


def add_frame_size_options(parser: argparse.ArgumentParser) -> None:
    """A tool's ``--height`` and ``--width``: the frame size of a ``.dat``
    recording (which records none; :mod:`.io`). They go together:
    :func:`check_frame_size` refuses one without the other."""
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
