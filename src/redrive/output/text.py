"""Text from a log shown on a terminal: names a log chose (topics, types, frame ids) may hold
escape sequences (``\\x1b[2J`` clears the screen) or rich markup (``[bold]``); shown through
:func:`shown`, they appear as the characters they are and change nothing on the screen.
"""

from __future__ import annotations

import re

__all__ = ["doc_summary", "printable", "shown"]

#: a Sphinx cross-reference (``:mod:`redrive.x``` , ``:func:`~a.b```) or an inline literal
_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")
_LITERAL = re.compile(r"``([^`]+)``")


def printable(text: str) -> str:
    """``text`` with every non-printable character (C0/C1 controls, escape, DEL, line and
    paragraph separators …) written as its Python escape (``\\x1b``, ``\\n``, ``\\u2028``), and a
    backslash as ``\\\\`` so that the result reads back unambiguously; printable text as it is."""
    if text.isprintable() and "\\" not in text:
        return text
    out = []
    for char in text:
        if char == "\\":
            out.append("\\\\")
        elif char.isprintable():
            out.append(char)
        else:
            out.append(repr(char)[1:-1])
    return "".join(out)


def shown(text: str) -> str:
    """``text`` safe to hand to a rich console: :func:`printable`, and rich markup escaped."""
    from rich.markup import escape

    return escape(printable(text))


def doc_summary(doc: str | None) -> str:
    """The first paragraph of a docstring as one line of plain text, for a terminal table: the
    lines joined with single spaces, Sphinx roles (``:mod:`a.b``` → ``a.b``) and double-backtick
    literals (````x```` → ``x``) unwrapped."""
    first = (doc or "").strip().split("\n\n", 1)[0]
    text = " ".join(first.split())
    return _LITERAL.sub(r"\1", _ROLE.sub(r"\1", text))
