"""``vbl-robust verify RUN``: every job row of a stored run checked against its own evaluations, its box, its sample
and the digest written when it was committed (:func:`vbl_robust.campaigns.verify.check_store`); ``--head`` also
checks the store's head digest against the one a report printed. Exit 0 with a one-line summary when everything
matches, 1 naming each row that does not (and each committed row missing), 2 for a store that cannot be read."""

from __future__ import annotations

from typing import Annotated

import typer

from . import options as o
from .common import fail

Head = Annotated[str | None, typer.Option("--head", help="The head digest a report of this run printed (its "
                                          "provenance): exit 1 unless the store's head is this one.")]


def verify(run: o.StoredRun, head: Head = None) -> None:
    """Check a run's rows against their own evaluations and their digests (exit 1 naming each row that disagrees)."""
    from vbl_robust.campaigns.verify import check_store
    from vbl_robust.store.core import ResultStore

    if head is not None and (len(head) != 64 or any(c not in "0123456789abcdef" for c in head.lower())):
        fail(f"--head {head}: not a SHA-256 (64 hex digits)")
    try:
        with ResultStore.open_existing(run) as store:
            if not store.holds_campaign() and store.count() == 0:
                fail(f"{run}: the results store holds no campaign yet: nothing to verify")
            check = check_store(store)
    except (ValueError, FileNotFoundError) as exc:
        fail(str(exc))
    for f in check.findings:
        typer.echo(f.line())
    moved = head is not None and check.head != head.lower()
    if moved:
        typer.echo(f"head: {check.head} in the store, {head.lower()} expected: the store is not the one reported")
    if check.findings or moved:
        rows = len(check.inconsistent)
        typer.secho(f"{run}: {rows} row(s) inconsistent, {len(check.findings)} finding(s)"
                    f"{'; head differs' if moved else ''} — {check.summary()}", err=True, fg=typer.colors.RED)
        raise typer.Exit(1)
    typer.echo(f"{run}: {check.summary()}")
