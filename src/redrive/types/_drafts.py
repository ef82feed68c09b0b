"""Drafts: mutable twins of frozen slotted dataclasses, for code that builds many at once.

A frozen dataclass refuses attribute assignment, so building one without its ``__init__`` means
setting every slot through the slot's descriptor (``Cls.__dict__[name].__set__``: a
method-wrapper called with an argument tuple, ≈ 600 instructions a slot).  A *draft* is a plain
class with the same slots in the same order: the interpreter stores its attributes with its
specialised slot store (≈ 15 instructions), and assigning ``draft.__class__ = Cls`` — which
CPython allows between heap types whose instances have the same layout — makes it an instance
of the frozen class (≈ 550 instructions), indistinguishable from one its ``__init__`` built:
same type, slots, equality, hashing, repr and pickling.  For a class of 7 fields that is a
quarter of the setters' cost.

Only code that sets *every* field, with values it has made what ``__init__`` would make of
them (a reader's checked chunk of messages, a decoder's batch of clouds), builds through a
draft; everything else calls the constructor.
"""

from __future__ import annotations

from typing import Any

__all__ = ["draft_class"]


def draft_class(cls: type[Any]) -> type[Any]:
    """The draft class of ``cls``, a slotted class without ``__dict__`` (a frozen dataclass with
    ``slots=True``): its ``__slots__`` on a plain class.  Set every slot of a draft, then
    assign ``draft.__class__ = cls``.

    Raises:
        TypeError: ``cls`` has no ``__slots__`` of its own, or its instances' layout differs
            from the draft's (another base with slots, a ``__dict__``): CPython then refuses
            the ``__class__`` assignment, which is tried once here.
    """
    slots = cls.__dict__.get("__slots__")
    if not isinstance(slots, tuple) or cls.__base__ is not object:
        msg = f"{cls.__qualname__}: a draft needs a class of object with a __slots__ tuple"
        raise TypeError(msg)
    namespace = {"__slots__": slots, "__module__": cls.__module__, "__doc__": None}
    draft = type(f"{cls.__name__}Draft", (), namespace)
    probe = draft()
    probe.__class__ = cls  # TypeError when the layouts differ
    return draft
