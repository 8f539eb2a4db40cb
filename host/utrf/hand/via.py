"""How :class:`~utrf.hand.Hand` shows its parts' methods as its own: ``Hand.move`` is
``Via("_motion", HandMotion.move)``, so ``hand.move`` is the motion part's bound method, with
its signature and docstring; the method has one home, the part."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any, Concatenate, Generic, ParamSpec, Self, TypeVar, overload

S = TypeVar("S")
P = ParamSpec("P")
R = TypeVar("R")


class Via(Generic[S, P, R]):
    """A method of the Hand that is one of its part's: the part is the attribute ``part`` of
    the Hand, and the method keeps its name."""

    def __init__(self, part: str, method: Callable[Concatenate[S, P], R]) -> None:
        self.part = part
        self.method = method
        self.name = method.__name__
        self.__doc__ = method.__doc__

    def __set_name__(self, owner: type, name: str) -> None:
        if name != self.name:  # one name for one thing, on the Hand and on its part
            raise TypeError(f"{owner.__name__}.{name} shows a method named {self.name}")

    def __repr__(self) -> str:
        """The part's method and its signature, as ``help(Hand)`` shows it."""
        sig = inspect.signature(self.method)
        call = sig.replace(parameters=list(sig.parameters.values())[1:])
        return f"{self.method.__qualname__}{call}"

    @overload
    def __get__(self, hand: None, owner: type | None = None) -> Self: ...

    @overload
    def __get__(self, hand: object, owner: type | None = None) -> Callable[P, R]: ...

    def __get__(self, hand: object, owner: type | None = None) -> Any:
        if hand is None:
            return self
        bound: Callable[P, R] = getattr(getattr(hand, self.part), self.name)
        return bound
