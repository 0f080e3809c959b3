"""A griffe extension for the API reference: docstrings and signatures as users meet them.

* The docstrings use reStructuredText roles (``:class:`~aiofins.Client```, ``:meth:`read```),
  which Markdown would show as they are typed; they become code spans (``Client``, ``read``),
  a ``~`` keeping only the last dotted name as Sphinx does.
* A function made with ``@asynccontextmanager`` is shown as what it is to a caller, a plain
  function returning an async context manager (``async with aiofins.connect(url) as plc``),
  not as the async generator it is written as.
* An attribute documented by ``#:`` comments above it (Sphinx's convention, used for enum
  members, dataclass fields and module constants throughout the source) gets them as its
  docstring: an enum's page lists its members with their meanings.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:class|meth|func|attr|data|mod|exc|obj|const):`(~?)([^`]+)`")


TITLED = re.compile(r"(.+?)\s*<([^>]+)>")


def _code(match: re.Match[str]) -> str:
    short, target = match.group(1), match.group(2)
    titled = TITLED.fullmatch(target)  # :attr:`Endpoint.key <aiofins.endpoint.Endpoint.key>`
    if titled:
        return f"`{titled.group(1)}`"
    return f"`{target.rsplit('.', 1)[-1] if short else target}`"


class ApiReference(griffe.Extension):
    """Rewrites docstrings and async context manager signatures once the package is loaded."""

    def on_object(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if isinstance(obj, griffe.Attribute) and obj.docstring is None:
            comment = _comment_above(obj)
            if comment:
                obj.docstring = griffe.Docstring(comment, parent=obj)
        if obj.docstring is not None:
            obj.docstring.value = ROLE.sub(_code, obj.docstring.value)
        if isinstance(obj, griffe.Function) and _is_async_context_manager(obj):
            obj.labels.discard("async")
            if isinstance(obj.returns, griffe.ExprSubscript):  # AsyncIterator[X]
                obj.returns = f"AbstractAsyncContextManager[{obj.returns.slice}]"


def _is_async_context_manager(function: griffe.Function) -> bool:
    return any(str(d.value).endswith("asynccontextmanager") for d in function.decorators)


def _comment_above(attribute: griffe.Attribute) -> str:
    """The ``#:`` comment lines just above ``attribute``'s first line, as text."""
    if attribute.lineno is None or attribute.lines_collection is None:
        return ""
    try:
        lines = attribute.lines_collection[attribute.filepath]  # type: ignore[index]
    except (KeyError, TypeError):
        return ""
    found: list[str] = []
    index = attribute.lineno - 2
    while index >= 0 and lines[index].strip().startswith("#:"):
        found.append(lines[index].strip()[2:].strip())
        index -= 1
    return " ".join(reversed(found))
