"""What the modules compiled by mypyc (docs/packaging.md) need from plain Python."""

from __future__ import annotations

from typing import TypeVar

_C = TypeVar("_C", bound=type)


def python_class(cls: _C) -> _C:
    """Keep ``cls`` a Python class where its module is compiled (returns it unchanged).

    mypyc makes each class of a compiled module a native class, unless the class has a
    decorator mypyc does not know, as this one. An exception class whose base also derives
    from a builtin exception other than ``Exception`` (``FinsTimeout`` is a
    ``TimeoutError``, ``ConnectionLost`` a ``ConnectionError``) cannot be native.
    """
    return cls
