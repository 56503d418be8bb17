"""Turns library errors into one-line messages and a non-zero exit."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import click

from usd_garment.body.io import BodyModelError

#: Library exceptions that mean bad input rather than a bug.
USER_ERRORS: tuple[type[Exception], ...] = (BodyModelError, ValueError, OSError)


@contextmanager
def user_errors() -> Iterator[None]:
    """Re-raise bad-input errors as ``click.ClickException`` (one line, exit status 1)."""
    try:
        yield
    except USER_ERRORS as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise click.ClickException(message) from exc
