"""The checking decorator that :mod:`wgse_mmseg.fileio.spike_files`,
:mod:`wgse_mmseg.apis.walk_plan` and :mod:`wgse_mmseg.apis.recording_walk`
still apply to their entry points, with the kinds they (and
:mod:`wgse_mmseg.fileio.spike_arrays`) name.

``@declare(path=Path(), height=SIDE)`` checks the bound arguments of every
call before the body runs and raises
:class:`~wgse_mmseg.argument_checks.ArgumentError` naming the entry point
and the argument. Every other public entry point checks its arguments in
its own body (:mod:`wgse_mmseg.argument_checks`); the kinds are the
command line's (:mod:`wgse_mmseg.command_line`).
"""
import functools
import inspect
from typing import Callable

from ..command_line import (LAYOUT, NUM_STEPS, SIDE, Argument,  # noqa
                            Flag, Integer, Number, Path)

__all__ = []


def declare(**arguments: Argument) -> Callable[[Callable], Callable]:
    """Check ``arguments`` of a function on every call before its body runs
    (defaults included)."""

    def wrap(function: Callable) -> Callable:
        signature = inspect.signature(function)
        unknown = set(arguments) - set(signature.parameters)
        if unknown:
            raise TypeError(f'{function.__qualname__} declares '
                            f'{sorted(unknown)}, which it does not take')
        entry = function.__name__

        @functools.wraps(function)
        def checked(*args, **kwargs):
            try:
                bound = signature.bind(*args, **kwargs)
            except TypeError as err:
                raise TypeError(f'{entry}: {err}') from None
            bound.apply_defaults()
            for name, argument in arguments.items():
                argument.check(bound.arguments[name], entry, name)
            return function(*args, **kwargs)

        return checked

    return wrap
