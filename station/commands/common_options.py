"""What the record commands share: the ``--db`` option and the one-line refusal (exit 2)."""

from __future__ import annotations

from typing import Annotated

import typer

from station.kernel.errors import StationError
from station.store.default_url import ENV_VAR

DbOption = Annotated[
    str | None,
    typer.Option("--db", help=f"database URL (default: ${ENV_VAR} or sqlite:///station.sqlite)"),
]


def refuse(exc: StationError) -> typer.Exit:
    """Print ``exc`` as one line on stderr; the exit (code 2) to raise."""
    typer.echo(f"error: {exc}", err=True)
    return typer.Exit(2)
