"""One error base: every exception class the package defines derives from
:class:`wgse_mmseg.WgseError` and from a built-in class other than
``Exception`` (``ValueError``, ``OSError``, ``RuntimeError``, ...), so that
``except WgseError`` catches every error of the package and ``except
ValueError`` still catches a wrong value."""
import importlib
import inspect
import pkgutil

import wgse_mmseg
from wgse_mmseg import WgseError
from wgse_mmseg.argument_checks import ArgumentError

wgse_mmseg.register_all_modules()


def _defined_exceptions():
    """``dotted name -> class`` of every exception class defined in a
    module of the package (a module whose optional dependency is absent is
    left out)."""
    found = {}
    for info in pkgutil.walk_packages(wgse_mmseg.__path__, 'wgse_mmseg.'):
        try:
            module = importlib.import_module(info.name)
        except ModuleNotFoundError as err:
            if err.name and err.name.startswith('wgse_mmseg'):
                raise
            continue
        for value in vars(module).values():
            if inspect.isclass(value) and issubclass(value, BaseException) \
                    and value.__module__ == module.__name__:
                found[f'{value.__module__}.{value.__qualname__}'] = value
    return found


def _builtin_bases(cls):
    """The built-in exception classes above ``cls``, ``Exception`` and
    ``BaseException`` aside."""
    return [base for base in cls.__mro__
            if base.__module__ == 'builtins' and
            base not in (Exception, BaseException, object)]


def test_every_error_of_the_package_derives_from_the_base():
    found = _defined_exceptions()
    assert len(found) >= 12 and 'wgse_mmseg.errors.WgseError' in found
    apart = sorted(name for name, cls in found.items()
                   if not issubclass(cls, WgseError))
    assert not apart, f'derive these from wgse_mmseg.WgseError too: {apart}'
    plain = sorted(name for name, cls in found.items()
                   if cls is not WgseError and not _builtin_bases(cls))
    assert not plain, (f'give these the built-in class of their errors '
                       f'(ValueError, OSError, ...): {plain}')


def test_the_check_sees_an_error_apart():
    """The reading above tells an error of the base from one apart."""
    class Apart(ValueError):
        pass

    assert _builtin_bases(ArgumentError) == [ValueError]
    assert _builtin_bases(Apart) == [ValueError]
    assert not issubclass(Apart, WgseError)
    assert issubclass(ArgumentError, WgseError)


def test_a_wrong_argument_is_caught_either_way():
    from wgse_mmseg.core import WGSE
    for base in (WgseError, ValueError):
        try:
            WGSE(level=0)
        except base as err:
            assert str(err) == 'WGSE: level must be an integer >= 1, got 0'
        else:
            raise AssertionError('WGSE(level=0) was accepted')
