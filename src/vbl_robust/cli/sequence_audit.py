"""``vbl-robust audit --sequences N|DIR --sustain K``: the worst error one θ sustains over approach sequences.

For every sequence (generated: N sequences of ``--frames`` frames at ``--rate`` Hz; or a LARD V2 dataset
directory grouped into sequences, :mod:`vbl_robust.data.sequence`) and every search method, the search maximises
:class:`~vbl_robust.sequences.SequenceObjective` (one θ held over the whole sequence, the error sustained over
``K`` consecutive frames) with the audit's box, budget, seed and detector. Written to ``--out``:

- ``sequences.json``: settings, detector identity, and per sequence the frames' distances and times, the nominal
  (unperturbed) and worst per-frame errors and failure reasons, and one entry per method;
- ``sequences.csv``: one row per sequence (the worst over the methods): worst sustained error, θ, longest run of
  breached frames, the distance from the runway threshold where the first run of ≥ K breached frames starts;
- ``sequence_frames.csv``: one row per frame: distance, time, nominal and worst error and reason;
- ``figures/sequence_errors.png``: error against distance along the approach, nominal and worst θ;
- ``report.html``: that figure and the table of ``sequences.csv`` in one self-contained page.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import typer

from .common import fail

CSV_FIELDS = ("sequence_id", "airport", "frames", "sustain", "verdict", "worst_sustained_m", "method",
              "longest_run_frames", "longest_run_s", "breached_frames", "failed_frames", "breach_start_m",
              "breach_start_frame", "first_breach_m", "window_start", "nominal_sustained_m", "nominal_breached_frames")


def load_sequences(source: str, *, frames: int, rate: float, seed: int, width: int, height: int) -> tuple[list, dict]:
    """Sequences of ``--sequences``: a count (generated) or a LARD V2 dataset directory."""
    from vbl_robust.campaigns.samples import find_lard_files
    from vbl_robust.data import read_lard_sequences
    from vbl_robust.scenes import generate_sequences

    text = str(source).strip()
    if text.isdigit():
        n = int(text)
        if n < 1:
            fail(f"--sequences {source}: need at least 1 sequence")
        try:
            seqs = generate_sequences(n, frames, rate, seed, width=width, height=height)
        except (ValueError, RuntimeError) as exc:
            fail(str(exc))
        return seqs, {"kind": "synthetic sequences", "n": n, "frames": frames, "rate_hz": rate, "seed": seed,
                      "width": width, "height": height}
    if not Path(text).is_dir():
        fail(f"--sequences {source}: expected a number of sequences or a LARD V2 dataset directory")
    try:
        csv_path, db_path = find_lard_files(text)
        seqs = read_lard_sequences(csv_path, db_path, rate_hz=rate)
    except (ValueError, FileNotFoundError) as exc:
        fail(str(exc))
    if not seqs:
        fail(f"--sequences {source}: the dataset has no usable rows")
    return seqs, {"kind": "lard sequences", "csv": str(csv_path), "db": str(db_path), "sequences": len(seqs)}


def _clean(x: Any) -> Any:
    """JSON-safe: NumPy scalars and arrays to Python, non-finite floats to None."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(x) else None
    return x


def run_sequence_audit(out: Path, source: str, *, frames: int, rate: float, seed: int, width: int, height: int,
                       sustain: int, box: Any, methods: tuple[str, ...], max_evals: int | None,
                       max_seconds: float | None, early_stop: bool, pnp: str, detector: Any, quiet: bool,
                       config: dict, unsupported: dict[str, bool]) -> None:
    """Run the sequence audit and write its files (module docstring); one-line errors for user mistakes."""
    from vbl_robust.constants import EPS_SAFE_M, PENALTY_M, Verdict
    from vbl_robust.search import maximize
    from vbl_robust.sequences import SequenceObjective, nominal_theta, plot_errors_along_approach

    given = [name for name, on in unsupported.items() if on]
    if given:
        fail(f"--sequences: {', '.join(given)} do(es) not apply to a sequence audit")
    if not (max_evals or max_seconds):
        fail("--sequences: give a budget (--max-evals or --max-seconds)")
    sequences, source_info = load_sequences(source, frames=frames, rate=rate, seed=seed, width=width, height=height)
    det = detector.build()
    out.mkdir(parents=True, exist_ok=True)
    entries, rows, frame_rows, curves = [], [], [], []
    for q, seq in enumerate(sequences):
        try:
            objective = SequenceObjective(seq, det, box, pnp, sustain=sustain)
        except ValueError as exc:
            fail(f"sequence {seq.id!r} ({len(seq)} frames): {exc}")
        nominal = objective.evaluate(nominal_theta(box))
        per_method, worst, worst_rec = [], None, None
        for method in methods:
            try:
                res = maximize(objective, box, method, max_evals=max_evals or None, max_seconds=max_seconds,
                               stop_above=EPS_SAFE_M if early_stop else None, seed=seed)
            except ValueError as exc:
                fail(f"sequence {seq.id!r}, method {method}: {exc}")
            x = nominal_theta(box)[0] if res.x is None else np.asarray(res.x, dtype=np.float64)
            rec = objective.evaluate(x[None])
            facts = rec.summary(0, EPS_SAFE_M)
            facts.update(method=method, nfev=int(res.nfev), status=str(res.status), failures=dict(res.failures))
            per_method.append(facts)
            if worst is None or facts["sustained_m"] > worst["sustained_m"]:
                worst, worst_rec = facts, rec
        nom = nominal.summary(0, EPS_SAFE_M)
        verdict = Verdict.BREACH if worst["sustained_m"] > EPS_SAFE_M else Verdict.NO_BREACH_FOUND
        airport = seq.samples[0].meta.get("airport", "")
        entries.append({
            "sequence_id": seq.id, "airport": airport, "frames": len(seq), "rate_hz": seq.rate_hz,
            "frame_index": seq.frame_index, "times_s": seq.times, "distances_m": seq.distances_m,
            "verdict": str(verdict), "worst": {**worst, "errors_m": worst_rec.loss[:, 0],
                                               "reasons": [r[0] for r in worst_rec.reasons]},
            "nominal": {**nom, "errors_m": nominal.loss[:, 0], "reasons": [r[0] for r in nominal.reasons]},
            "methods": per_method,
        })
        row = {"sequence_id": seq.id, "airport": airport, "frames": len(seq), "sustain": sustain,
               "verdict": str(verdict), "worst_sustained_m": worst["sustained_m"],
               "nominal_sustained_m": nom["sustained_m"], "nominal_breached_frames": nom["breached_frames"]}
        row.update({k: worst[k] for k in CSV_FIELDS if k in worst and k not in row})
        row.update({f"worst_{n}": worst[n] for n in box.names})
        rows.append(row)
        for f, s in enumerate(seq.samples):
            frame_rows.append({"sequence_id": seq.id, "frame_index": int(seq.frame_index[f]), "image": s.id,
                               "time_s": float(seq.times[f]), "distance_m": float(seq.distances_m[f]),
                               "nominal_error_m": float(nominal.loss[f, 0]), "nominal_reason": nominal.reasons[f][0],
                               "worst_error_m": float(worst_rec.loss[f, 0]), "worst_reason": worst_rec.reasons[f][0]})
        curves.append({"sequence_id": seq.id, "distances_m": seq.distances_m, "nominal_m": nominal.loss[:, 0],
                       "worst_m": worst_rec.loss[:, 0]})
        seq.drop_pixels()
        if not quiet:
            theta = ", ".join(f"{n}={worst[n]:.3g}" for n in box.names)
            start = "–" if worst["breach_start_m"] is None else f"{worst['breach_start_m']:.0f} m"
            typer.echo(f"[{q + 1}/{len(sequences)}] {seq.id}: worst sustained {worst['sustained_m']:.1f} m at {theta} "
                       f"({worst['method']}); longest breached run {worst['longest_run_frames']} frames; "
                       f"lasting breach from {start}")

    summary = {"command": config, "source": source_info, "detector": detector.identity(),
               "box": box.to_dict(), "sustain": sustain,
               "eps_safe_m": EPS_SAFE_M, "penalty_m": PENALTY_M, "methods": list(methods), "sequences": entries}
    (out / "sequences.json").write_text(json.dumps(_clean(summary), indent=1) + "\n", encoding="utf-8")
    _write_csv(out / "sequences.csv", rows, [*CSV_FIELDS, *(f"worst_{n}" for n in box.names)])
    _write_csv(out / "sequence_frames.csv", frame_rows, list(frame_rows[0]))
    figure = plot_errors_along_approach(curves, out / "figures" / "sequence_errors.png", eps_m=EPS_SAFE_M,
                                        penalty_m=PENALTY_M, title=f"Error along the approach (sustain k = {sustain})")
    breached = sum(r["verdict"] == str(Verdict.BREACH) for r in rows)
    headline = (f"{len(rows)} sequences, {breached} with an error sustained over {sustain} frames above "
                f"{EPS_SAFE_M:g} m")
    report = write_report(out, Path(figure), out / "sequences.csv", headline=headline, details=(
        f"Box {box.to_dict()}; methods {', '.join(methods)}; detector {detector.identity().get('name', '?')}; "
        f"sustain k = {sustain} frames; ε_safe = {EPS_SAFE_M:g} m, failure penalty {PENALTY_M:g} m."))
    typer.echo(f"{headline}; results in {out / 'sequences.json'}, {out / 'sequences.csv'}; figure {figure}; "
               f"report {report}")


def write_report(out: Path, figure: Path, csv_path: Path, *, headline: str, details: str) -> Path:
    """``out/report.html``: the figure and the per-sequence table of ``csv_path``, self-contained."""
    from vbl_robust.constants import Verdict
    from vbl_robust.report.html import esc, fmt_num, img, page, table

    with open(csv_path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        fields = list(reader.fieldnames or [])
        lines = list(reader)

    def cell(v: str) -> str:
        try:
            return fmt_num(int(v)) if v.lstrip("-").isdigit() else fmt_num(float(v))
        except ValueError:
            return esc(v) if v else "–"

    body = [f"<h1>vbl-robust — sequence audit</h1><p><b>{esc(headline)}</b>.</p>", f'<p class="note">{esc(details)}</p>',
            img(figure.read_bytes(), figure.stem, "Error against the distance from the runway threshold along each "
                "approach: the unperturbed θ (dashed) and the worst θ found (solid)."),
            f"<h2>Per sequence ({esc(csv_path.name)})</h2>",
            table(lines, [(k, k, cell) for k in fields], left=("sequence_id", "airport", "verdict", "method"),
                  row_class=lambda r: "breach" if r.get("verdict") == str(Verdict.BREACH) else "")]
    path = out / "report.html"
    path.write_text(page("vbl-robust sequence audit", "\n".join(body)), encoding="utf-8")
    return path


def _write_csv(path: Path, rows: list[dict], fields: list[str]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: ("" if v is None else v) for k, v in _clean(r).items()})
