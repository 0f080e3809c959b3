"""A griffe extension for the API reference: docstrings and signatures as users meet them.

* The docstrings use reStructuredText roles (``:class:`~aiofins.Client```, ``:meth:`read```),
  which Markdown would show as they are typed; they become code spans (``Client``, ``read``),
  a ``~`` keeping only the last dotted name as Sphinx does.
* A function made with ``@asynccontextmanager`` is shown as what it is to a caller, a plain
  function returning an async context manager (``async with aiofins.connect(url) as plc``),
  not as the async generator it is written as.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:class|meth|func|attr|data|mod|exc|obj|const):`(~?)([^`]+)`")


def _code(match: re.Match[str]) -> str:
    short, target = match.group(1), match.group(2)
    return f"`{target.rsplit('.', 1)[-1] if short else target}`"


class ApiReference(griffe.Extension):
    """Rewrites docstrings and async context manager signatures once the package is loaded."""

    def on_object(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = ROLE.sub(_code, obj.docstring.value)
        if isinstance(obj, griffe.Function) and _is_async_context_manager(obj):
            obj.labels.discard("async")
            if isinstance(obj.returns, griffe.ExprSubscript):  # AsyncIterator[X]
                obj.returns = f"AbstractAsyncContextManager[{obj.returns.slice}]"


def _is_async_context_manager(function: griffe.Function) -> bool:
    return any(str(d.value).endswith("asynccontextmanager") for d in function.decorators)
