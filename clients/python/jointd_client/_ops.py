"""The `operation` tag: which OpenAPI operations a client method calls
(tests/test_coverage.py checks every operation has one)."""

from typing import Any, Callable, TypeVar

F = TypeVar("F", bound=Callable[..., Any])


def operation(*ids: str) -> Callable[[F], F]:
    """Marks a method as the client's call of these OpenAPI operations."""

    def mark(f: F) -> F:
        setattr(f, "operations", ids)
        return f

    return mark
