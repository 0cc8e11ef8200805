"""``vbl-robust check DATA``: can a run use every row of a LARD V2 dataset? Per row: the image present, decodable
and of the stated size (:func:`vbl_robust.data.check.check_images`), the corner labels against the reprojected
runway corners (:func:`vbl_robust.data.check.check_labels`), and whether an audit would use the row, skip it (not
its image's target runway) or fail to measure it. Exit 0 when every row can be used, 1 when a row would not be
measured, 2 for a DATA that cannot be read as a dataset."""

from __future__ import annotations

import json
import logging
import math
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer

from vbl_robust.atomic import atomic_write

from . import options as o
from .common import check_writable, fail, one_line, set_verbosity

#: Rows the table shows without ``--all`` (the rows with a problem first).
SHOWN_ROWS = 20

Data = Annotated[Path, typer.Argument(help="A LARD V2 dataset directory: one metadata CSV, one runway DB JSON, the "
                                      "images (as `audit --lard DATA` reads it).", show_default=False)]
AllRows = Annotated[bool, typer.Option("--all", help=f"Print every row (default: at most {SHOWN_ROWS}, the rows "
                                       "with a problem first).")]
JsonOut = Annotated[Path | None, typer.Option("--json", help="Also write every row and the summary to this JSON "
                                              "file.")]
SequencesFlag = Annotated[bool, typer.Option("--sequences", help="Read DATA as `audit --sequences DATA` does: rows "
                                             "grouped into approach sequences (a sequence with one unusable frame "
                                             "is not measured at all).")]


@dataclass
class RowCheck:
    """What ``check`` finds about one CSV row."""

    row: int
    image: str
    runway: str
    audit: str  # "use", "skip" or "unmeasured"
    why: str
    image_ok: bool
    image_problem: str
    image_kind: str
    size: tuple[int, int] | None
    stated_size: tuple[int, int]
    labels_max_px: float
    labels_off: tuple[str, ...]
    labels_exact: bool | None
    sequence: str | None = None
    frame: int | None = None

    @property
    def problem(self) -> bool:
        return self.audit == "unmeasured" or bool(self.labels_off)

    def to_json(self) -> dict[str, Any]:
        return {
            "row": self.row, "image": self.image, "runway": self.runway, "audit": self.audit, "why": self.why,
            "image_ok": self.image_ok, "image_problem": self.image_problem, "image_kind": self.image_kind,
            "size": None if self.size is None else list(self.size), "stated_size": list(self.stated_size),
            "labels_max_px": None if math.isnan(self.labels_max_px) else self.labels_max_px,
            "labels_off": list(self.labels_off), "labels_exact": self.labels_exact,
            "sequence": self.sequence, "frame": self.frame,
        }


def check(
    data: Data, all_rows: AllRows = False, json_out: JsonOut = None, sequences: SequencesFlag = False,
    quiet: o.Quiet = False, verbose: o.Verbose = False,
) -> None:
    """Check a LARD V2 dataset before a run: each row's image (present, decodable, of the stated size), its labels
    against the reprojected runway corners, and whether an audit would use or skip it. Exit 0: every row usable;
    1: some row would not be measured; 2: DATA is not a dataset."""
    # torch (the samples) and pymap3d (the data) behind these: not for ``--help``
    from vbl_robust.campaigns.samples import find_lard_files
    from vbl_robust.data.check import check_images
    from vbl_robust.data.lard_read import read_lard
    from vbl_robust.data.sequence import group_sequences

    quiet = set_verbosity(quiet=quiet, verbose=verbose)
    if not data.exists():
        fail(f"{data}: no such directory (DATA is a LARD V2 dataset directory: metadata CSV, runway DB JSON, images)")
    if not data.is_dir():
        fail(f"{data}: not a directory (DATA is a LARD V2 dataset directory: metadata CSV, runway DB JSON, images)")
    _check_json_target(json_out)
    with one_line(ValueError, OSError):
        csv_path, db_path = find_lard_files(data, option="")
        used = read_lard(csv_path, db_path)  # exactly what audit --lard reads
        with _quiet_reader():  # the reader's warning about inconsistent rows is given once, by the read above
            every = read_lard(csv_path, db_path, target_runway_only=False)
    if not every:
        fail(f"{csv_path}: the dataset has no rows")
    frames: dict[int, tuple[str, int]] = {}
    seqs = []
    if sequences:
        with one_line(ValueError, prefix="--sequences: "):
            seqs = group_sequences(used)
        frames = {f.meta["row"]: (seq.id, int(i)) for seq in seqs for f, i in zip(seq.samples, seq.frame_index,
                                                                                     strict=True)}
    image_checks = _with_progress(lambda progress: check_images(every, root=csv_path.parent, progress=progress),
                                  len(every), quiet)
    rows = _rows(every, used, image_checks, frames)
    shown = rows if all_rows else _first_shown(rows)
    if not quiet:
        _print_table(rows, shown, sequences)
    summary = _summary(rows, seqs)
    typer.echo(_summary_line(summary))
    if json_out is not None:
        doc = {"data": str(data), "csv": str(csv_path), "runway_db": str(db_path), "sequences": sequences,
               "summary": summary, "rows": [r.to_json() for r in rows]}
        json_out.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(json_out, json.dumps(doc, indent=1, allow_nan=False) + "\n")
        typer.echo(f"rows written to {json_out}")
    if summary["unmeasured"]:
        raise typer.Exit(1)


def _check_json_target(path: Path | None) -> None:
    if path is not None:
        check_writable("--json", path)


@contextmanager
def _quiet_reader() -> Iterator[None]:
    """The LARD reader's warnings silenced inside (the second read of the same file)."""
    logger = logging.getLogger("vbl_robust.data.lard_read")
    disabled, logger.disabled = logger.disabled, True
    try:
        yield
    finally:
        logger.disabled = disabled


def _with_progress(work: Any, total: int, quiet: bool) -> Any:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    columns = (TextColumn("[bold]images"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, disable=quiet, transient=True) as bar:
        task = bar.add_task("images", total=total)
        return work(lambda done, n: bar.update(task, completed=done, total=n))


def _rows(every: list, used: list, image_checks: list, frames: dict[int, tuple[str, int]]) -> list[RowCheck]:
    from vbl_robust.data.check import check_labels

    kept = {s.meta["row"]: s for s in used}
    by_image = {s.meta["image"].strip(): s for s in used}
    checks = dict(zip((s.meta["row"] for s in every), image_checks, strict=True))
    # a sequence is one job: a frame the run cannot read leaves the whole sequence unmeasured
    broken: dict[str, str] = {}
    for row, (seq, frame) in frames.items():
        c = checks[row]
        if not c.ok and seq not in broken:
            broken[seq] = f"frame {frame} of sequence {seq} ({c.path}): {c.problem}"
    out = []
    for s in every:
        row, c, labels = s.meta["row"], checks[s.meta["row"]], check_labels(s)
        seq, frame = frames.get(row, (None, None))
        if row not in kept:
            target = by_image.get(s.meta["image"].strip())
            audit, why = "skip", "not its image's target runway" + (
                f" (the audit reads row {target.meta['row']}, {target.meta['airport']} {target.meta['runway']})"
                if target is not None else "")
        elif not c.ok:
            audit, why = "unmeasured", c.problem
        elif seq is not None and seq in broken:
            audit, why = "unmeasured", broken[seq]
        else:
            audit, why = "use", ""
        out.append(RowCheck(
            row=row, image=c.path or s.id, runway=f"{s.meta['airport']} {s.meta['runway']}", audit=audit, why=why,
            image_ok=c.ok, image_problem=c.problem, image_kind=c.kind, size=c.size,
            stated_size=(int(s.width), int(s.height)), labels_max_px=labels.max_px, labels_off=labels.off,
            labels_exact=labels.exact, sequence=seq, frame=frame,
        ))
    return out


def _first_shown(rows: list[RowCheck]) -> list[RowCheck]:
    """At most :data:`SHOWN_ROWS` rows: unmeasured first, then labels off the camera, then the rest (CSV order
    within each)."""
    def rank(r: RowCheck) -> int:
        return 0 if r.audit == "unmeasured" else 1 if r.labels_off else 2

    return sorted(rows, key=lambda r: (rank(r), r.row))[:SHOWN_ROWS]


def _print_table(rows: list[RowCheck], shown: list[RowCheck], sequences: bool) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="rows of the dataset" + ("" if len(shown) == len(rows) else
                                                 f" (the first {len(shown)} of {len(rows)}, problems first)"))
    table.add_column("row", justify="right")
    table.add_column("image", overflow="fold")
    table.add_column("runway", no_wrap=True)
    if sequences:
        table.add_column("sequence / frame", overflow="fold")
    table.add_column("image file", overflow="fold")
    table.add_column("size (px)", no_wrap=True)
    table.add_column("labels Δ (px)", justify="right")
    table.add_column("audit", overflow="fold")
    for r in shown:
        size = "–" if r.size is None else f"{r.size[0]}x{r.size[1]}"
        if r.size is not None and r.size != r.stated_size:
            size += f" (CSV {r.stated_size[0]}x{r.stated_size[1]})"
        labels = "–" if math.isnan(r.labels_max_px) else f"{r.labels_max_px:.2f}"
        if r.labels_off:
            labels = f"[yellow]{labels} off ({', '.join(r.labels_off)})[/]"
        file_cell = "ok" if r.image_ok else f"[red]{r.image_problem}[/]"
        audit = {"use": "use", "skip": f"skip: {r.why}", "unmeasured": f"[red]not measured: {r.why}[/]"}[r.audit]
        if r.audit == "unmeasured" and r.why == r.image_problem:
            audit = "[red]not measured[/]"
        seq = [] if not sequences else ["–" if r.sequence is None else f"{r.sequence} / {r.frame}"]
        table.add_row(str(r.row), r.image, r.runway, *seq, file_cell, size, labels, audit)
    Console().print(table)
    if len(shown) < len(rows):
        typer.echo(f"… {len(rows) - len(shown)} more row(s) not shown: --all prints them, --json PATH writes them")
    typer.echo("labels Δ: the largest distance between a corner label (x_TR_exact… when the CSV has them, else "
               "x_TR…)\nand that corner reprojected with the row's camera; 'off': beyond the reader's tolerance")


def _summary(rows: list[RowCheck], seqs: list) -> dict[str, Any]:
    from vbl_robust.data.check import IMAGE_PROBLEMS

    unmeasured = [r for r in rows if r.audit == "unmeasured"]
    kinds = Counter(r.image_kind for r in unmeasured if r.image_kind)
    out = {
        "rows": len(rows),
        "usable": sum(r.audit == "use" for r in rows),
        "skipped": sum(r.audit == "skip" for r in rows),
        "unmeasured": len(unmeasured),
        "problems": sum(r.problem for r in rows),
        "labels_off": sum(bool(r.labels_off) for r in rows),
        "image_problems": {IMAGE_PROBLEMS[k]: n for k, n in kinds.items()},
        "labels_max_px": max((r.labels_max_px for r in rows if not math.isnan(r.labels_max_px)), default=None),
    }
    in_broken_sequence = sum(r.audit == "unmeasured" and not r.image_kind for r in rows)
    if in_broken_sequence:
        out["image_problems"]["in a sequence with an unusable frame"] = in_broken_sequence
    if seqs:
        broken = {r.sequence for r in unmeasured if r.sequence is not None}
        out["sequences"] = len(seqs)
        out["sequences_unmeasured"] = len(broken)
    return out


def _summary_line(s: dict[str, Any]) -> str:
    skipped = f"{s['skipped']} skipped" + (" (not their image's target runway)" if s["skipped"] else "")
    parts = [f"{n} {what}" for what, n in s["image_problems"].items()]
    if s["labels_off"]:
        parts.append(f"{s['labels_off']} with labels off the camera")
    problems = f"{s['problems']} with problems" + (f" ({', '.join(parts)})" if parts else "")
    line = f"{s['rows']} rows: {s['usable']} usable, {skipped}, {problems}"
    if s["unmeasured"]:
        line += f"; {s['unmeasured']} would not be measured"
    if "sequences" in s:
        line += f"; {s['sequences']} sequences, {s['sequences_unmeasured']} not measured"
    if s["labels_max_px"] is not None:
        line += f"; labels within {s['labels_max_px']:.2f} px of the reprojected corners"
    return line
