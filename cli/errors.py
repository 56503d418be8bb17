"""Turns library errors into one-line messages and a non-zero exit."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TypeVar

import click

from usd_garment.body.io import BodyModelError

F = TypeVar("F", bound=Callable[..., object])

#: Library exceptions that mean bad input rather than a bug.
USER_ERRORS: tuple[type[Exception], ...] = (BodyModelError, ValueError, FileNotFoundError)


@contextmanager
def user_errors() -> Iterator[None]:
    """Re-raise bad-input errors as ``click.ClickException`` (one line, exit status 1)."""
    try:
        yield
    except USER_ERRORS as exc:
        raise click.ClickException(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
