"""The integer check every argument validation in the package shares."""
from numbers import Integral

__all__ = ['is_integer']


def is_integer(value, minimum=None) -> bool:
    """Whether ``value`` is an integer (``int`` or a NumPy integer; ``bool``
    is not one) and, with ``minimum``, at least ``minimum``."""
    return isinstance(value, Integral) and not isinstance(value, bool) and \
        (minimum is None or bool(value >= minimum))
