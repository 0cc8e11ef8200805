"""An adversarial probe over every command of ``vbl-robust`` (issue 59's goal): ≥ 200 probes, default workers.

Each probe runs the installed CLI in a subprocess (timeout per probe) on fixtures this script builds in a temporary
directory — tiny synthetic LARD datasets, a finished oracle run, a risk run, a copy of the shipped model as a user's
``.pt``, an ONNX export — and classifies its own outcome:

* **ok**: the expected exit code (0 for what must work, 2 for a refusal with one ``error:`` line, 1 where the docs
  say so), no traceback, no marker file left by stored code, a run directory unchanged by a refusal, markup escaped;
* **weak**: works, but not as well as it should (a message of several lines, exit 1 where 2 is documented, a slow
  refusal, a refusal after partial work);
* **bad**: a traceback, a hang (timeout), exit 0 on nonsense, code run from data, a wrong number, a run directory
  changed by a refusal.

Prints a Markdown table (probe, command, expected, exit, outcome, note) and a summary line; ``--out FILE`` writes
it there instead; exit status 1 when any probe is bad. Never passes ``--workers`` (default workers)::

    python benchmarks/adversarial_probes.py --out /tmp/probes.md [--only SUBSTRING] [--keep]
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import shutil
import signal
import sqlite3
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VBL = str(Path(sys.executable).with_name("vbl-robust"))
if not Path(VBL).exists():
    VBL = str(ROOT / ".venv/bin/vbl-robust")
SHIPPED_PT = ROOT / "src/vbl_robust/models/runway_yolov8n_pose.pt"
MODELS_DIR = ROOT / "src/vbl_robust/models"
TIMEOUT = 120.0
SLOW_REFUSAL_S = 30.0
SVG = "<svg onload=alert(1)>"
LEVEL = {"ok": 0, "weak": 1, "bad": 2}

ENV = {k: v for k, v in os.environ.items() if k != "VBL_ROBUST_WORKERS"}
ENV.update(YOLO_OFFLINE="1", YOLO_CONFIG_DIR=str(ROOT / ".cache/ultralytics"), MPLBACKEND="Agg",
           PYTHONIOENCODING="utf-8")


# ---------------------------------------------------------------------------------------------------------------
# running


@dataclass
class Result:
    rc: int | None  # None: timed out
    out: str
    seconds: float
    cmd: str


def _show(args) -> str:
    parts = []
    for a in args:
        a = os.fsdecode(a) if isinstance(a, bytes) else str(a)
        parts.append(a)
    return " ".join(parts)


def run(args, *, timeout: float = TIMEOUT, stdin=subprocess.DEVNULL, cwd: Path | None = None) -> Result:
    """``vbl-robust ARGS`` with stdout and stderr together; rc None on timeout (the process group is killed)."""
    argv = [VBL, *[a if isinstance(a, bytes) else str(a) for a in args]]
    t0 = time.monotonic()
    p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=stdin, env=ENV,
                         cwd=cwd or ROOT, start_new_session=True)
    try:
        out, _ = p.communicate(timeout=timeout)
        rc = p.returncode
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        out, _ = p.communicate()
        rc = None
    return Result(rc, out.decode("utf-8", "replace"), time.monotonic() - t0, _show(["vbl-robust", *args]))


def snapshot(d: Path) -> dict[str, str]:
    """Every file under ``d`` with its SHA-256 (a directory's absence is {'<absent>': ''})."""
    d = Path(d)
    if not d.exists():
        return {"<absent>": ""}
    if d.is_file():
        return {d.name: hashlib.sha256(d.read_bytes()).hexdigest()}
    snap = {}
    for f in sorted(d.rglob("*")):
        if f.is_file():
            snap[str(f.relative_to(d))] = hashlib.sha256(f.read_bytes()).hexdigest()
        elif f.is_dir():
            snap[str(f.relative_to(d)) + "/"] = ""
    return snap


def diff(a: dict, b: dict) -> str:
    changed = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    return ", ".join(changed[:4]) + (" …" if len(changed) > 4 else "")


BOILER = ("Usage: ", "Try '")


def message_lines(out: str) -> list[str]:
    return [ln for ln in out.splitlines() if ln.strip() and not ln.startswith(BOILER)]


# ---------------------------------------------------------------------------------------------------------------
# probes


@dataclass
class Probe:
    name: str
    args: list = field(default_factory=list)
    expect: int | tuple = 2  # 0 works, 2 refusal, 1 documented; a tuple: any of them
    unchanged: tuple = ()  # directories / files that must be byte-identical afterwards
    absent: tuple = ()  # paths that must not exist afterwards (a refusal creates nothing)
    marker: Path | None = None  # a file stored code would create
    check: Callable[[Result], list] | None = None  # extra findings: [(level, note)]
    fn: Callable[[], tuple] | None = None  # a custom probe: returns (Result, findings)
    timeout: float = TIMEOUT
    setup: Callable[[], None] | None = None
    one_line: bool = True  # a refusal must be one error line (not for click's own help screen)


@dataclass
class Outcome:
    probe: Probe
    res: Result
    level: str
    note: str


def classify(p: Probe, res: Result, before: dict, extra: list) -> tuple[str, str]:
    found: list[tuple[str, str]] = list(extra)
    expect = p.expect if isinstance(p.expect, tuple) else (p.expect,)
    if res.rc is None:
        found.append(("bad", f"hang: killed after {p.timeout:.0f} s"))
    if "Traceback" in res.out:
        last = [ln for ln in res.out.splitlines() if ln.strip()][-1:]
        found.append(("bad", "traceback: " + (last[0][:100] if last else "")))
    if p.marker is not None and Path(p.marker).exists():
        found.append(("bad", "code from data ran (marker file created)"))
    for d, snap in before.items():
        now = snapshot(Path(d))
        if now != snap:
            found.append(("bad", f"{Path(d).name} changed: {diff(snap, now)}"))
    if res.rc is not None and res.rc not in expect:
        if res.rc == 0 and 0 not in expect:
            found.append(("bad", "exit 0 on what must be refused"))
        elif 0 in expect and res.rc != 0:
            msg = message_lines(res.out)
            found.append(("bad", f"failed what must work: {(msg[-1] if msg else '')[:110]}"))
        elif res.rc == 1 and 2 in expect:
            found.append(("weak", "exit 1 where a refusal (2) is documented"))
        elif res.rc == 2 and 1 in expect:
            found.append(("weak", "exit 2 where 1 is documented"))
        else:
            found.append(("bad" if res.rc not in (1, 2) else "weak", f"exit {res.rc}, expected {expect}"))
    if res.rc == 2 and 2 in expect and p.one_line:
        msg = message_lines(res.out)
        errs = [ln for ln in msg if ln.lower().startswith("error")]
        if len(errs) != 1 or len(msg) != 1:
            found.append(("weak", f"refusal message of {len(msg)} lines ({len(errs)} error lines)"))
        if res.seconds > SLOW_REFUSAL_S:
            found.append(("weak", f"slow refusal ({res.seconds:.0f} s)"))
    if p.absent and res.rc != 0:
        made = [str(Path(a).name) for a in p.absent if Path(a).exists()]
        if made and res.rc == 2:
            found.append(("bad", "a refusal created " + ", ".join(made)))
        elif made:
            found.append(("weak", "failed after partial work (created " + ", ".join(made) + ")"))
    if not found:
        msg = message_lines(res.out)
        if res.rc == 2 and msg:
            return "ok", msg[0][:120]
        return "ok", ""
    level = max((lv for lv, _ in found), key=LEVEL.get)
    return level, "; ".join(n for _, n in found)


def run_probe(p: Probe) -> Outcome:
    if p.setup:
        p.setup()
    before = {str(d): snapshot(Path(d)) for d in p.unchanged}
    extra: list = []
    try:
        if p.fn is not None:
            res, extra = p.fn()
        else:
            res = run(p.args, timeout=p.timeout)
            if p.check is not None and res.rc is not None:
                extra = list(p.check(res) or [])
    except Exception as exc:  # the probe itself broke: say so, as bad (not silently ok)
        res = Result(-1, f"probe error: {exc!r}", 0.0, " ".join(map(str, p.args)) or p.name)
        extra = [("bad", f"probe could not run: {exc!r}"[:140])]
    level, note = classify(p, res, before, extra)
    return Outcome(p, res, level, note)


# ---------------------------------------------------------------------------------------------------------------
# fixtures


class Fx:
    """The fixtures, built once per script run under ``T``."""

    def __init__(self, T: Path):
        self.T = T
        self.n = 0

    def fresh(self, stem: str = "out") -> Path:
        self.n += 1
        return self.T / "fresh" / f"{stem}{self.n:03d}"

    def build(self) -> None:
        T = self.T
        (T / "fresh").mkdir(parents=True, exist_ok=True)
        self.marker = T / "MARKER"
        log = []

        def must(res: Result, what: str) -> None:
            log.append(f"{what}: exit {res.rc} in {res.seconds:.0f} s")
            if res.rc != 0:
                raise SystemExit(f"fixture {what} failed (exit {res.rc}):\n{res.out[-3000:]}")

        self.ds = T / "ds"
        must(run(["scenes", "--n", "2", "--width", "160", "--height", "160", "--out", self.ds, "--seed", "1"]),
             "scenes")
        self.csv_name = next(self.ds.glob("*.csv")).name
        self.ds3 = T / "ds3"
        must(run(["scenes", "--n", "3", "--width", "160", "--height", "160", "--out", self.ds3, "--seed", "2"]),
             "scenes 3")
        self.run = T / "runs" / "run"
        self.run_args = ["--oracle", "--n", "2", "--max-evals", "4", "--roll", "5", "--methods", "random",
                         "--no-landscape", "--width", "160", "--height", "160", "-q"]
        must(run(["audit", *self.run_args, "--out", self.run]), "audit run")
        self.risk = T / "runs" / "risk"
        self.risk_args = ["--oracle", "--n", "2", "--max-evals", "128", "--roll", "5", "--methods", "mc",
                          "--width", "160", "--height", "160", "-q"]
        must(run(["risk", *self.risk_args, "--out", self.risk]), "risk run")
        self.pt = T / "user.pt"
        shutil.copyfile(SHIPPED_PT, self.pt)
        self.onnx = T / "m.onnx"
        code = ("import sys; from vbl_robust.detect.onnx import export_onnx; "
                "export_onnx(sys.argv[1], sys.argv[2], trust=True, imgsz=320)")
        t0 = time.monotonic()
        try:
            p = subprocess.run([sys.executable, "-c", code, str(SHIPPED_PT), str(self.onnx)], env=ENV,
                               capture_output=True, timeout=240)
            ok = p.returncode == 0 and self.onnx.exists()
        except subprocess.TimeoutExpired:
            ok = False
        log.append(f"onnx export: {'ok' if ok else 'failed'} in {time.monotonic() - t0:.0f} s")
        if not ok:
            self.onnx = None
        self.plugin = T / "plug.py"
        self.plugin.write_text(
            "from pathlib import Path\n"
            "from vbl_robust.detect.oracle import OracleDetector\n"
            "def make(**kw):\n    return OracleDetector()\n"
            f"def marking(**kw):\n    Path({str(self.marker)!r}).touch()\n    return OracleDetector()\n"
            "def notdet(**kw):\n    return 42\n"
            "def boom(**kw):\n    raise RuntimeError('boom')\n")
        (T / "syntax.py").write_text("def make(:\n")
        self.log = log

    # helpers building hostile copies ------------------------------------------------------------------------

    def copy_run(self, name: str, src: Path | None = None) -> Path:
        dst = self.T / "runs" / name
        if dst.exists():
            shutil.rmtree(dst)
        shutil.copytree(src or self.run, dst)
        return dst

    def sql(self, run: Path, statement: str, args: tuple = ()) -> Path:
        con = sqlite3.connect(run / "results.sqlite")
        try:
            con.execute(statement, args)
            con.commit()
        finally:
            con.close()
        return run

    def evil(self, name: str = "evil") -> Path:
        ident = {"kind": "factory", "factory": "subprocess:run", "name": "factory: subprocess:run", "path": None,
                 "sha256": None, "options": {"args": f"touch {self.marker}", "shell": True}}
        return self.sql(self.copy_run(name), "UPDATE campaign SET detector_json = ? WHERE id = 1",
                        (json.dumps(ident),))

    def copy_ds(self, name: str, src: Path | None = None) -> Path:
        dst = self.T / "data" / name
        if dst.exists():
            shutil.rmtree(dst)
        shutil.copytree(src or self.ds, dst)
        return dst

    def rows(self, ds: Path) -> tuple[list[str], list[dict]]:
        with open(ds / self.csv_name, newline="", encoding="utf-8") as f:
            r = csv.DictReader(f, delimiter=";")
            return list(r.fieldnames), list(r)

    def write_rows(self, ds: Path, fields: list[str], rows: list[dict]) -> None:
        with open(ds / self.csv_name, "w", newline="", encoding="utf-8") as f:
            w = csv.DictWriter(f, fieldnames=fields, delimiter=";")
            w.writeheader()
            w.writerows(rows)

    def ds_edit(self, name: str, **changes) -> Path:
        """A copy of ``ds`` whose first row has ``changes`` (field → value)."""
        d = self.copy_ds(name)
        fields, rows = self.rows(d)
        rows[0].update(changes)
        self.write_rows(d, fields, rows)
        return d

    def ds_image_named(self, name: str, image_name: str) -> Path:
        """A copy of ``ds`` whose first image is renamed to ``image_name`` (when the file system takes it)."""
        d = self.copy_ds(name)
        fields, rows = self.rows(d)
        old = d / rows[0]["image"]
        try:
            old.rename(old.with_name(image_name))
        except OSError:
            pass
        rows[0]["image"] = str(Path(rows[0]["image"]).with_name(image_name))
        self.write_rows(d, fields, rows)
        return d

    def ds_image_bytes(self, name: str, data: Callable[[bytes], bytes]) -> Path:
        d = self.copy_ds(name)
        _, rows = self.rows(d)
        img = d / rows[0]["image"]
        img.write_bytes(data(img.read_bytes()))
        return d


def png_header(width: int, height: int) -> bytes:
    """A PNG that claims ``width`` × ``height`` (grey, 8 bit) with one tiny IDAT (decoding would need w·h bytes)."""
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b"")


# ---------------------------------------------------------------------------------------------------------------
# checks


def contains(*words: str) -> Callable[[Result], list]:
    def check(res: Result) -> list:
        missing = [w for w in words if w not in res.out]
        return [("weak", "output lacks " + ", ".join(repr(w) for w in missing))] if missing else []
    return check


def not_empty(res: Result) -> list:
    return [] if res.out.strip() else [("weak", "prints nothing")]


def file_escaped(path: Callable[[], Path | list[Path]]) -> Callable[[Result], list]:
    """Raw ``<svg onload`` in any of the files is bad (markup from a name)."""
    def check(res: Result) -> list:
        paths = path()
        paths = paths if isinstance(paths, list) else [paths]
        raw = [p.name for p in paths if p.exists() and SVG.encode() in p.read_bytes()]
        if not any(p.exists() for p in paths):
            return [("weak", "no file written to check for escaping")]
        return [("bad", "raw markup in " + ", ".join(raw))] if raw else []
    return check


def json_out(res: Result) -> list:
    text = res.out  # standard output and error together: the JSON starts at its first line opening with { or [
    lines = text.splitlines(keepends=True)
    start = next((i for i, ln in enumerate(lines) if ln.startswith(("{", "["))), 0)
    try:
        json.loads("".join(lines[start:]))
        return []
    except ValueError:
        return [("weak", "--format json output is not JSON")]


def jobs_of(run: Path) -> list[tuple]:
    con = sqlite3.connect(f"file:{run / 'results.sqlite'}?mode=ro", uri=True)
    try:
        return sorted(con.execute("SELECT key, status, verdict, round(worst_m, 6), nfev FROM jobs").fetchall())
    finally:
        con.close()


def children(pid: int) -> list[int]:
    out = []
    for st in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = st.read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) == pid:
                out.append(int(st.parent.name))
        except (OSError, IndexError, ValueError):
            pass
    return out


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        return state != "Z"
    except OSError:
        return False


# ---------------------------------------------------------------------------------------------------------------
# the probes


def probes(fx: Fx) -> list[Probe]:
    P = []
    run_, risk_ = fx.run, fx.risk
    small = ["--oracle", "--n", "1", "--max-evals", "2", "--roll", "5", "--methods", "random", "--no-landscape",
             "--width", "160", "--height", "160", "-q", "--no-report"]

    def add(name, args=(), expect=2, **kw):
        P.append(Probe(name, list(args), expect, **kw))

    # --- every command's help, version, unknown command -------------------------------------------------------
    for c in ("scenes", "check", "audit", "demo", "risk", "reproduce", "truth", "report", "bundle", "merge",
              "train", "ship", "harden", "zones", "verify"):
        add(f"help {c}", [c, "--help"], 0, check=contains("Usage"))
    add("version", ["--version"], 0, check=not_empty)
    add("unknown command", ["frobnicate"], 2)
    add("no command (the help screen)", [], (0, 2), one_line=False, check=contains("Commands"))

    # --- audit: bad option values (a fresh --out each: nothing may be created) --------------------------------
    bad_audit = [
        ("max-evals negative", ["--max-evals", "-1"]), ("max-evals word", ["--max-evals", "abc"]),
        ("max-evals nan", ["--max-evals", "nan"]), ("max-evals huge", ["--max-evals", "1e99"]),
        ("max-evals empty", ["--max-evals", ""]), ("max-evals over cap", ["--max-evals", "99999999999"]),
        ("max-evals 0 without seconds", ["--max-evals", "0"]),
        ("max-seconds negative", ["--max-seconds", "-1"]), ("max-seconds nan", ["--max-seconds", "nan"]),
        ("max-seconds inf", ["--max-seconds", "inf"]), ("max-seconds word", ["--max-seconds", "soon"]),
        ("n zero", ["--n", "0"]), ("n negative", ["--n", "-2"]), ("n over cap", ["--n", "100001"]),
        ("n float", ["--n", "1.5"]), ("seed negative", ["--seed", "-1"]), ("seed 2^64", ["--seed", str(2**64)]),
        ("width 15", ["--width", "15"]), ("width 8193", ["--width", "8193"]), ("width zero", ["--width", "0"]),
        ("height negative", ["--height", "-160"]), ("height word", ["--height", "tall"]),
        ("oracle-noise negative", ["--oracle-noise", "-1"]), ("oracle-noise nan", ["--oracle-noise", "nan"]),
        ("oracle-noise inf", ["--oracle-noise", "inf"]),
        ("roll '5,'", ["--roll", "5,"]), ("roll ',5'", ["--roll", ",5"]), ("roll nan", ["--roll", "nan"]),
        ("roll inf", ["--roll", "inf"]), ("roll 1e309", ["--roll", "1e309"]), ("roll word", ["--roll", "abc"]),
        ("roll empty range 5,5", ["--roll", "5,5"]), ("roll reversed", ["--roll", "10,-10"]),
        ("roll empty", ["--roll", ""]), ("roll 720", ["--roll", "720"]), ("roll three values", ["--roll", "1,2,3"]),
        ("roll negative half-width", ["--roll", "-5"]),
        ("contrast one value", ["--contrast", "5"]), ("contrast 0,0", ["--contrast", "0,0"]),
        ("contrast negative", ["--contrast", "-1,2"]), ("contrast nan", ["--contrast", "nan,1"]),
        ("contrast reversed", ["--contrast", "1.4,0.7"]),
        ("perturb unknown family", ["--perturb", "bogus=1,2"]), ("perturb blur negative", ["--perturb", "blur_px=-1,2"]),
        ("perturb nan", ["--perturb", "haze=nan,1"]), ("perturb '='", ["--perturb", "="]),
        ("perturb one value", ["--perturb", "haze=1"]), ("perturb trailing comma", ["--perturb", "haze=0,"]),
        ("perturb contrast twice", ["--perturb", "contrast=0.8,1.2", "--contrast", "0.7,1.4"]),
        ("perturb same family twice", ["--perturb", "haze=0,0.2", "--perturb", "haze=0,0.3"]),
        ("perturb huge range", ["--perturb", "yaw_deg=-1e300,1e300"]),
        ("methods empty", ["--methods", ""]), ("methods unknown", ["--methods", "bogus"]),
        ("methods trailing comma", ["--methods", "random,"]), ("methods commas", ["--methods", ",,,"]),
        ("method-option malformed", ["--method-option", "bogus"]),
        ("method-option unknown method", ["--method-option", "nomethod.x=1"]),
        ("method-option unknown option", ["--method-option", "random.no_such_option=1"]),
        ("method-option python tag", ["--method-option", "random.x=!!python/object/apply:os.system ['true']"]),
        ("method-option alias bomb", ["--method-option", "random.x=&a [*a, *a]"]),
        ("method-option empty", ["--method-option", "random.="]),
        ("lipschitz negative", ["--lipschitz", "-1"]), ("lipschitz nan", ["--lipschitz", "nan"]),
        ("lipschitz word", ["--lipschitz", "steep"]), ("lipschitz too many", ["--lipschitz", "1,2,3"]),
        ("pnp unknown", ["--pnp", "magic"]), ("executor unknown", ["--executor", "slurm"]),
        ("clock unknown", ["--clock", "sundial"]), ("engine unknown", ["--engine", "tensorrt9"]),
        ("device unknown", ["--device", "tpu"]), ("device cuda:99", ["--device", "cuda:99"]),
        ("detector unknown", ["--detector", "threestage"]), ("target unknown", ["--target", "everything"]),
        ("sustain without sequences", ["--sustain", "3"]), ("sustain zero", ["--sustain", "0"]),
        ("frames zero", ["--frames", "0"]), ("rate negative", ["--rate", "-1", "--sequences", "1"]),
        ("rate nan", ["--rate", "nan", "--sequences", "1"]), ("sequences word", ["--sequences", "abc"]),
        ("sequences zero", ["--sequences", "0"]), ("sequences negative", ["--sequences", "-1"]),
        ("monitor-residual negative", ["--monitor-residual", "-1"]),
        ("monitor-residual nan", ["--monitor-residual", "nan"]),
        ("monitor-sigma with apgd", ["--monitor-sigma", "5", "--methods", "apgd"]),
        ("refine-zones negative", ["--refine-zones", "-1"]),
        ("model missing file", ["--model", str(fx.T / "nope.pt")]),
        ("model and oracle", ["--model", "default"]),
        ("address without ray", ["--address", "127.0.0.1:1"]),
        ("csv into /proc", ["--csv", "/proc/nope/x.csv"]),
        ("lard missing", ["--lard", str(fx.T / "no-such-dir")]),
        ("lard is a file", ["--lard", str(fx.plugin)]),
        ("plugin-digest without plugin", ["--plugin-digest", "ab" * 32]),
        ("plugin with oracle", ["--detector-plugin", f"{fx.plugin}:make"]),
    ]
    for name, extra in bad_audit:
        out = fx.fresh("audit")
        add(f"audit {name}", ["audit", *small, *extra, "--out", out], 2, absent=(out,))
    # the same kind aimed at the finished run: it must stay byte-identical
    for name, extra in [("other oracle noise", ["--oracle-noise", "3"]), ("other seed", ["--seed", "7"]),
                        ("other size", ["--width", "96", "--height", "96"]), ("other roll", ["--roll", "7"]),
                        ("bad roll", ["--roll", "5,"]), ("bad max-evals", ["--max-evals", "-4"]),
                        ("user pt untrusted", ["--model", fx.pt]),
                        ("user pt trusted (other detector)", ["--model", fx.pt, "--trust-model"])]:
        args = [*fx.run_args, *extra, "--out", run_]
        if "--model" in extra:
            args.remove("--oracle")
        add(f"audit refusal keeps run: {name}", ["audit", *args], 2, unchanged=(run_,))
    add("audit rerun of a finished run", ["audit", *fx.run_args, "--out", run_, "--no-report"], 0,
        check=lambda r: [] if jobs_of(run_) == fx.run_jobs else [("bad", "a rerun changed the rows")])
    add("audit --config RUN/config.yaml repeats the run",
        ["audit", "--config", run_ / "config.yaml", "--no-report", "-q"], 0,
        check=lambda r: [] if jobs_of(run_) == fx.run_jobs else [("bad", "the config did not repeat the run")])
    add("audit --out is a file", ["audit", *small, "--out", fx.plugin], 2, unchanged=(fx.plugin,))
    add("audit --out under /proc", ["audit", *small, "--out", "/proc/vbl-robust-probe"], 2)
    add("audit --out empty", ["audit", *small, "--out", ""], 2)
    long_out = fx.T / "fresh" / ("L" * 300)
    add("audit --out 300-char name", ["audit", *small, "--out", long_out], 2)
    add("audit --out non-UTF-8 name", ["audit", *small, "--out", os.fsencode(str(fx.T / "fresh")) + b"/bad\xff\xfe"],
        (0, 2))
    hostile = fx.T / "runs" / f"x|{SVG}"
    add("audit --out hostile name (report escaped)",
        ["audit", "--oracle", "--n", "1", "--max-evals", "2", "--roll", "5", "--methods", "random",
         "--no-landscape", "--width", "160", "--height", "160", "-q", "--out", hostile], 0,
        check=file_escaped(lambda: [hostile / "report.html"]))

    # --- audit: detectors --------------------------------------------------------------------------------------
    base_det = ["--n", "1", "--max-evals", "2", "--roll", "5", "--methods", "random", "--no-landscape",
                "--width", "160", "--height", "160", "-q", "--no-report"]
    add("audit user .pt without --trust-model", ["audit", *base_det, "--model", fx.pt, "--out", o := fx.fresh()], 2,
        absent=(o,))
    add("audit user .pt with --trust-model", ["audit", *base_det, "--model", fx.pt, "--trust-model",
                                              "--out", fx.fresh()], 0, timeout=240)
    for name, data in [("0-byte", b""), ("truncated", SHIPPED_PT.read_bytes()[:5000]), ("random bytes", os.urandom(4096)),
                       ("text", b"not a model\n")]:
        f = fx.T / f"bad_{name.replace(' ', '_')}.pt"
        f.write_bytes(data)
        add(f"audit .pt {name} (trusted)", ["audit", *base_det, "--model", f, "--trust-model",
                                            "--out", o := fx.fresh()], 2, absent=(o,))
    add("audit --model a directory", ["audit", *base_det, "--model", fx.T, "--out", o := fx.fresh()], 2, absent=(o,))
    add("audit --model .txt", ["audit", *base_det, "--model", fx.plugin, "--out", o := fx.fresh()], 2, absent=(o,))
    for name, data in [("0-byte", b""), ("random bytes", os.urandom(4096))]:
        f = fx.T / f"bad_{name.replace(' ', '_')}.onnx"
        f.write_bytes(data)
        add(f"audit .onnx {name}", ["audit", *base_det, "--model", f, "--out", o := fx.fresh()], 2, absent=(o,))
    if fx.onnx is not None:
        add("audit ONNX export", ["audit", *base_det, "--model", fx.onnx, "--out", fx.fresh()], 0, timeout=240)
        for name, value in [("kpt_shape '[4, 3'", "[4, 3"), ("kpt_shape '4'", "4"), ("kpt_shape [5, 3]", "[5, 3]"),
                            ("names code", "__import__('os').system('touch MARKER')")]:
            f = fx.T / f"meta_{len(P)}.onnx"
            key = "names" if name.startswith("names") else "kpt_shape"
            fx_meta(fx.onnx, f, key, value)
            add(f"audit ONNX metadata {name}", ["audit", *base_det, "--model", f, "--out", o := fx.fresh()], 2,
                absent=(o,), marker=ROOT / "MARKER")
    # plug-ins: naming one on the command line is consent; from a --config file it is not
    add("audit plug-in file:factory", ["audit", *base_det, "--detector-plugin", f"{fx.plugin}:make",
                                       "--out", fx.fresh()], 0)
    for name, spec in [("not a detector", f"{fx.plugin}:notdet"), ("raises", f"{fx.plugin}:boom"),
                       ("missing factory", f"{fx.plugin}:nothing"), ("syntax error", f"{fx.T / 'syntax.py'}:make"),
                       ("missing module", "no_such_module_xyz:make"), ("no colon", "json"),
                       ("empty", ""), ("missing file", f"{fx.T / 'none.py'}:make")]:
        add(f"audit plug-in {name}", ["audit", *base_det, "--detector-plugin", spec, "--out", o := fx.fresh()], 2,
            absent=(o,))
    cfg = fx.T / "cfg_plugin.yaml"
    cfg.write_text(f"detector-plugin: {fx.plugin}:marking\nn: 1\nmax-evals: 2\nroll: '5'\nmethods: random\n")
    add("audit plug-in from --config without consent", ["audit", "--config", cfg, "--no-landscape", "--width", "160",
                                                        "--height", "160", "-q", "--out", o := fx.fresh()], 2,
        absent=(o,), marker=fx.marker)

    # --- audit: datasets -----------------------------------------------------------------------------------------
    lard = ["--n", "2", "--max-evals", "2", "--roll", "5", "--methods", "random", "--no-landscape", "--oracle",
            "-q", "--no-report"]
    add("audit --lard dataset", ["audit", *lard, "--lard", fx.ds, "--out", fx.fresh()], 0)
    ds_cases = [
        ("image missing", lambda: fx.ds_image_named("missing", "gone.jpg") and _rm_first(fx, "missing"), (1, 2)),
        ("image 0-byte", lambda: fx.ds_image_bytes("zero", lambda b: b""), 2),
        ("JPEG truncated to a third", lambda: fx.ds_image_bytes("third", lambda b: b[: len(b) // 3]), 2),
        ("image random bytes", lambda: fx.ds_image_bytes("rnd", lambda b: os.urandom(len(b))), 2),
        ("PNG claiming 30000x30000", lambda: fx.ds_image_bytes("huge", lambda b: png_header(30000, 30000)), 2),
        ("image ../ traversal", lambda: fx.ds_edit("trav", image="../../etc/passwd"), 2),
        ("image absolute path", lambda: fx.ds_edit("abs", image="/etc/passwd"), 2),
        ("width field nan", lambda: fx.ds_edit("wnan", width="nan"), 2),
        ("width field negative", lambda: fx.ds_edit("wneg", width="-160"), 2),
        ("width field huge", lambda: fx.ds_edit("whuge", width="99999999"), 2),
        ("corner nan", lambda: fx.ds_edit("cnan", x_TR="nan"), 2),
        ("corner empty", lambda: fx.ds_edit("cempty", x_TR=""), 2),
        ("altitude inf", lambda: fx.ds_edit("altinf", alt_cam="inf"), 2),
        ("airport not in runway DB", lambda: fx.ds_edit("noair", airport="ZZZZ"), 2),
        ("runway DB fifth corner", lambda: _fifth_corner(fx), 2),
        ("runway DB not JSON", lambda: _db_bytes(fx, "dbjunk", b"{not json"), 2),
        ("runway DB 0-byte", lambda: _db_bytes(fx, "db0", b""), 2),
        ("runway DB alias-free deep nesting", lambda: _db_bytes(fx, "dbdeep", b"[" * 100000 + b"]" * 100000), 2),
        ("CSV 0-byte", lambda: _csv_bytes(fx, "csv0", lambda b: b""), 2),
        ("CSV header only", lambda: _csv_bytes(fx, "csvhdr", lambda b: b.split(b"\n")[0] + b"\n"), 2),
        ("CSV truncated mid-row", lambda: _csv_bytes(fx, "csvcut", lambda b: b[: len(b) - 260]), 2),
        ("CSV non-UTF-8", lambda: _csv_bytes(fx, "csvlatin", lambda b: b.replace(b";", b";\xff", 30)), 2),
        ("CSV missing column", lambda: _drop_column(fx, "nocol", "x_TR"), 2),
        ("symlinked image outside", lambda: _symlink_image(fx), 2),
    ]
    for name, make, expect in ds_cases:
        o = fx.fresh()
        P.append(Probe(f"audit --lard {name}", [], expect, absent=(o,) if expect == 2 else (),
                       fn=_lazy_run(lambda make=make, o=o: ["audit", *lard, "--lard", make(), "--out", o])))
    def add_lazy(name, mk, expect, **kw):
        P.append(Probe(name, [], expect, fn=_lazy_run(mk, kw.pop("check", None)), **kw))
    o = fx.fresh()
    add_lazy("audit --lard JPEG truncated, --allow-unmeasured", lambda o=o: [
        "audit", *lard, "--allow-unmeasured", "--lard", fx.ds_image_bytes("third2", lambda b: b[: len(b) // 3]),
        "--out", o], 0)
    o = fx.fresh()
    add_lazy("audit --lard image name with | and markup (report escaped)", lambda o=o: [
        "audit", *lard[:-1], "--lard", fx.ds_image_named("markup", f"a|b{SVG}.jpg"), "--out", o], 0,
        check=file_escaped(lambda o=o: [o / "report.html"]))
    o = fx.fresh()
    add_lazy("audit --lard 300-char image name fails one sample", lambda o=o: [
        "audit", *lard, "--allow-unmeasured", "--lard", fx.ds_image_named("long", "n" * 300 + ".jpg"), "--out", o],
        (0, 1))
    o = fx.fresh()
    add_lazy("audit --lard non-UTF-8 image name", lambda o=o: [
        "audit", *lard, "--lard", _latin_name(fx), "--out", o], (0, 1, 2))

    # --- audit --config: hostile configs ------------------------------------------------------------------------
    cfgs = {
        "alias bomb": "a: &a [x,x,x,x,x,x,x,x,x]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\nc: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\n"
                      "d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]\ne: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]\n"
                      "f: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]\ng: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]\n"
                      "h: [*g,*g,*g,*g,*g,*g,*g,*g,*g]\n",
        "duplicated key": "seed: 1\nseed: 2\n",
        "boolean seed": "seed: true\n",
        "boolean max-evals": "max-evals: yes\n",
        "fraction max-evals": "max-evals: 1.5\n",
        "unknown key": "no-such-option: 1\n",
        "list at top": "- 1\n- 2\n",
        "scalar at top": "42\n",
        "python tag": f"seed: !!python/object/apply:os.system ['touch {fx.marker}']\n",
        "nan seed": "seed: .nan\n",
        "roll list": "roll: [5, 6, 7]\n",
        "tab indentation": "seed:\n\t1\n",
        "huge int": "seed: " + "9" * 5000 + "\n",
    }
    for name, text in cfgs.items():
        f = fx.T / f"cfg_{len(P)}.yaml"
        f.write_text(text)
        add(f"audit --config {name}", ["audit", *small, "--config", f, "--out", o := fx.fresh()], 2, absent=(o,),
            marker=fx.marker, timeout=60)
    f = fx.T / "cfg_latin.yaml"
    f.write_bytes(b"seed: 1\n# caf\xe9\n")
    add("audit --config non-UTF-8", ["audit", *small, "--config", f, "--out", o := fx.fresh()], 2, absent=(o,))
    f = fx.T / "cfg_big.yaml"
    f.write_text("# " + "x" * (1_200_000) + "\nseed: 1\n")
    add("audit --config 1.2 MB", ["audit", *small, "--config", f, "--out", o := fx.fresh()], 2, absent=(o,))
    add("audit --config /dev/zero", ["audit", *small, "--config", "/dev/zero", "--out", o := fx.fresh()], 2,
        absent=(o,), timeout=60)
    add("audit --config a directory", ["audit", *small, "--config", fx.T, "--out", o := fx.fresh()], 2, absent=(o,))
    add("audit --config missing", ["audit", *small, "--config", fx.T / "none.yaml", "--out", o := fx.fresh()], 2,
        absent=(o,))
    f = fx.T / "cfg_empty.yaml"
    f.write_text("")
    add("audit --config empty file", ["audit", *small, "--config", f, "--out", fx.fresh()], (0, 2))
    f = fx.T / "cfg_names.yaml"
    f.write_text("images: 1\nmax_evals: 2\nroll: '5'\nmethods: random\noracle: true\nlandscape: false\n"
                 "width: 160\nheight: 160\n")
    add("audit --config images:/max_evals: keys", ["audit", "--config", f, "-q", "--no-report", "--out", fx.fresh()], 0)

    # --- the store being written, kill -9 and SIGINT, then rerun ---------------------------------------------------
    P.append(Probe("audit kill -9 mid-run, rerun: rows identical to an uninterrupted run", fn=lambda: _kill_rerun(
        fx, signal.SIGKILL), expect=0, timeout=400))
    P.append(Probe("audit SIGINT mid-run, rerun: rows identical", fn=lambda: _kill_rerun(fx, signal.SIGINT),
                   expect=0, timeout=400))
    P.append(Probe("commands on a store being written", fn=lambda: _live_store(fx), expect=0, timeout=400))

    # --- demo -----------------------------------------------------------------------------------------------------
    for name, extra in [("n zero", ["--n", "0"]), ("max-evals zero", ["--max-evals", "0"]),
                        ("max-evals word", ["--max-evals", "x"]), ("engine unknown", ["--engine", "magic"]),
                        ("device unknown", ["--device", "quantum"]), ("seed negative", ["--seed", "-3"]),
                        ("config missing", ["--config", fx.T / "none.yaml"])]:
        add(f"demo {name}", ["demo", "--oracle", "-q", *extra, "--out", o := fx.fresh("demo")], 2, absent=(o,))
    add("demo --out is a file", ["demo", "--oracle", "-q", "--out", fx.plugin], 2, unchanged=(fx.plugin,))
    add("demo tiny oracle", ["demo", "--oracle", "--n", "1", "--max-evals", "2", "--no-landscape", "-q",
                             "--out", fx.fresh("demo")], 0, timeout=240)

    # --- risk -----------------------------------------------------------------------------------------------------
    rsmall = ["--oracle", "--n", "1", "--max-evals", "64", "--guide-evals", "8", "--roll", "5", "--width", "160", "--height", "160", "-q",
              "--no-report"]
    for name, extra in [
        ("tau negative", ["--tau", "-0.1"]), ("tau above 1", ["--tau", "2"]), ("tau nan", ["--tau", "nan"]),
        ("tau word", ["--tau", "low"]), ("delta 0", ["--delta", "0"]), ("delta 1", ["--delta", "1"]),
        ("delta nan", ["--delta", "nan"]), ("delta inf", ["--delta", "inf"]), ("max-evals 1", ["--max-evals", "1"]),
        ("guide-evals 0", ["--guide-evals", "0"]), ("methods unknown", ["--methods", "bogus"]),
        ("methods trailing comma", ["--methods", "mc,"]), ("methods empty", ["--methods", ""]),
        ("dist unknown", ["--dist", "roll_deg=cauchy:0,1"]), ("dist normal without sd", ["--dist", "roll_deg=normal:0"]),
        ("dist normal negative sd", ["--dist", "roll_deg=normal:0,-1"]),
        ("dist normal nan", ["--dist", "roll_deg=normal:nan,1"]),
        ("dist of a parameter not in the box", ["--dist", "haze=uniform"]),
        ("dist contradictory", ["--dist", "roll_deg=uniform", "--dist", "roll_deg=normal:0,1"]),
        ("dist malformed", ["--dist", "roll_deg"]), ("dist empty", ["--dist", ""]),
        ("guide-evals over max-evals", ["--methods", "guided", "--guide-evals", "100"]),
        ("roll '5,'", ["--roll", "5,"]), ("config alias bomb", ["--config", fx.T / "cfg_bomb_r.yaml"]),
    ]:
        add(f"risk {name}", ["risk", *rsmall, *extra, "--out", o := fx.fresh("risk")], 2, absent=(o,), timeout=60)
    (fx.T / "cfg_bomb_r.yaml").write_text(cfgs["alias bomb"])
    add("risk refusal keeps the risk run: other tau", ["risk", *fx.risk_args, "--tau", "0.2", "--out", risk_], 2,
        unchanged=(risk_,))
    add("risk refusal keeps the audit run (another campaign)", ["risk", *fx.risk_args, "--out", run_], 2,
        unchanged=(run_,))
    add("risk --methods mc --max-evals 16 (guided's default option unused)",
        ["risk", "--oracle", "--n", "1", "--max-evals", "16", "--roll", "5", "--width", "160", "--height", "160",
         "-q", "--no-report", "--methods", "mc", "--out", fx.fresh()], 0)
    add("risk normal dist", ["risk", *rsmall, "--methods", "mc", "--dist", "roll_deg=normal:0,2",
                             "--out", fx.fresh()], 0)
    add("risk rerun of a finished run", ["risk", *fx.risk_args, "--out", risk_, "--no-report"], 0)

    # --- reproduce ------------------------------------------------------------------------------------------------
    rp = ["--images", "1", "--oracle", "-q", "--no-report"]
    for name, extra in [
        ("unknown experiment", ["no-such-exp"]), ("experiment markup", [SVG]), ("images 0", ["spatial-1d", "--images", "0"]),
        ("time-budgets trailing comma", ["runtime-1d", "--time-budgets", "0.1,"]),
        ("time-budgets negative", ["runtime-1d", "--time-budgets", "-1"]),
        ("time-budgets nan", ["runtime-1d", "--time-budgets", "nan"]),
        ("time-budgets empty", ["runtime-1d", "--time-budgets", ""]),
        ("eval-budgets word", ["runtime-1d", "--eval-budgets", "many"]),
        ("eval-budgets zero", ["runtime-1d", "--eval-budgets", "0"]),
        ("grid-step inf", ["spatial-1d", "--grid-step", "inf"]), ("grid-step negative", ["spatial-1d", "--grid-step", "-1"]),
        ("grid-step nan", ["spatial-1d", "--grid-step", "nan"]),
        ("iterations 0", ["convergence", "--iterations", "0"]),
        ("family-grid negative", ["families", "--family-grid", "-1"]),
        ("resume-from missing", ["spatial-1d", "--resume-from", fx.T / "none"]),
        ("resume-from a run, not a bundle", ["spatial-1d", "--resume-from", run_]),
        ("check-against missing", ["spatial-1d", "--check-against", fx.T / "none"]),
        ("methods unknown", ["spatial-1d", "--methods", "bogus"]),
        ("method-option malformed", ["spatial-1d", "--method-option", "x"]),
        ("config python tag", ["spatial-1d", "--config", fx.T / "cfg_py_r.yaml"]),
        ("estimate probe-seconds 0", ["spatial-1d", "--estimate", "--probe-seconds", "0"]),
    ]:
        add(f"reproduce {name}", ["reproduce", *rp, *extra, "--out", o := fx.fresh("repro")], 2, absent=(o,),
            marker=fx.marker)
    (fx.T / "cfg_py_r.yaml").write_text(cfgs["python tag"])
    add("reproduce refusal keeps the audit run", ["reproduce", "spatial-1d", *rp, "--out", run_], 2,
        unchanged=(run_,))
    add("reproduce spatial-1d --estimate", ["reproduce", "spatial-1d", "--estimate", "--probe-seconds", "0.2",
                                            "--oracle"], 0, timeout=180)
    rep = fx.T / "runs" / "repro"
    add("reproduce spatial-1d tiny", ["reproduce", "spatial-1d", "--images", "1", "--oracle", "--max-evals", "4",
                                      "--grid-step", "5", "-q", "--no-report", "--out", rep], 0, timeout=240)

    # --- truth ----------------------------------------------------------------------------------------------------
    for name, counts in [("counts 0", "0"), ("counts negative", "-3"), ("counts word", "abc"),
                         ("counts trailing comma", "3,"), ("counts nan", "nan"), ("counts huge", "1000000000"),
                         ("counts two for a 1-D box", "3,3"), ("counts empty", ""), ("counts float", "2.5")]:
        add(f"truth {name}", ["truth", run_, "--counts", counts, "-q", "--no-report", "--out", o := fx.fresh("truth")],
            2, absent=(o,), unchanged=(run_,))
    add("truth missing run", ["truth", fx.T / "none", "--counts", "3", "-q"], 2)
    add("truth --out is the run itself", ["truth", run_, "--counts", "3", "-q", "--out", run_], 2, unchanged=(run_,))
    add("truth config bomb", ["truth", run_, "--counts", "3", "-q", "--config", fx.T / "cfg_bomb_r.yaml",
                              "--out", o := fx.fresh("truth")], 2, absent=(o,))
    add("truth tiny", ["truth", run_, "--counts", "3", "-q", "--no-report", "--out", fx.T / "runs" / "truth"], 0,
        unchanged=(run_,), timeout=240)
    add("truth of a risk run", ["truth", risk_, "--counts", "3", "-q", "--no-report",
                                "--out", o := fx.fresh("truth")], (0, 2), unchanged=(risk_,))

    # --- hostile stores -------------------------------------------------------------------------------------------
    def store_case(name, make, cmds):
        """``make()`` builds the hostile run lazily (in the probe); cmds: (label, args(run), expect, kw)."""
        cache = {}

        def get():
            if "run" not in cache:
                cache["run"] = make()
            return cache["run"]
        for label, argf, expect, kw in cmds:
            chk = kw.pop("check", None)
            P.append(Probe(f"{label} on {name}", [], expect, marker=fx.marker,
                           fn=_lazy_run(lambda argf=argf: argf(get()), chk), **kw))

    def all_cmds(expect_report, expect_verify, expect_truth=2, expect_zones=None, expect_merge=2):
        ez = expect_report if expect_zones is None else expect_zones
        return [("report", lambda r: ["report", r, "--out", fx.fresh("rep")], expect_report, {}),
                ("report md", lambda r: ["report", r, "--format", "md"], expect_report, {}),
                ("verify", lambda r: ["verify", r], expect_verify, {}),
                ("zones", lambda r: ["zones", r], ez, {}),
                ("truth", lambda r: ["truth", r, "--counts", "3", "-q", "--no-report",
                                     "--out", fx.fresh("truth")], expect_truth, {}),
                ("merge", lambda r: ["merge", r, "--into", fx.fresh("merge")], expect_merge, {})]

    store_case("a stored factory detector (subprocess:run)", lambda: fx.evil(),
               all_cmds(0, 0, 2, 0, 2) + [
                   ("audit --out", lambda r: ["audit", *fx.run_args, "--out", r], 2, {}),
                   ("bundle", lambda r: ["bundle", r.parent, "--out", fx.fresh("bundle")], (0, 2), {})])

    def zero():
        r = fx.copy_run("zero")
        (r / "results.sqlite").write_bytes(b"")
        return r
    store_case("a 0-byte store", zero, all_cmds(2, 2, 2, 2, 2))

    def truncated():
        r = fx.copy_run("trunc")
        s = r / "results.sqlite"
        s.write_bytes(s.read_bytes()[: s.stat().st_size // 2])
        return r
    store_case("a truncated store", truncated, all_cmds((1, 2), (1, 2), 2, (1, 2), 2))

    def junk():
        r = fx.copy_run("junk")
        (r / "results.sqlite").write_bytes(os.urandom(20000))
        return r
    store_case("a store of random bytes", junk, all_cmds(2, 2, 2, 2, 2))

    def edited():
        r = fx.copy_run("edited")
        key = sqlite3.connect(r / "results.sqlite").execute(
            "SELECT key FROM jobs WHERE kind='search' AND role='main' LIMIT 1").fetchone()[0]
        return fx.sql(r, "UPDATE jobs SET worst_m = 1.0 WHERE key = ?", (key,))
    store_case("a store with an edited worst_m", edited,
               [("verify", lambda r: ["verify", r], 1, {}),
                ("report md", lambda r: ["report", r, "--format", "md"], 1,  # written, but never exit 0
                 {"check": contains("inconsistent")}),
                ("merge", lambda r: ["merge", r, "--into", fx.fresh("merge")], 0, {"check": contains("inconsistent")}),
                ("zones", lambda r: ["zones", r], 0, {})])

    def nfev():
        r = fx.copy_run("nfev")
        return fx.sql(r, "UPDATE jobs SET nfev = -5 WHERE rowid = (SELECT min(rowid) FROM jobs WHERE kind='search')")
    store_case("a store with nfev = -5", nfev, [("verify", lambda r: ["verify", r], 1, {}),
                                               ("report csv", lambda r: ["report", r, "--format", "csv"], 1,
                                                {"check": lambda res: [("bad", "-5 reported")] if ",-5," in res.out
                                                 else []})])

    def theta():
        r = fx.copy_run("theta")
        return fx.sql(r, "UPDATE jobs SET worst_x_json = ? WHERE rowid = (SELECT min(rowid) FROM jobs WHERE "
                      "kind='search')", (json.dumps({"roll_deg": 90.0}),))
    store_case("a store with θ* outside its box", theta, [("verify", lambda r: ["verify", r], 1, {}),
                                                          ("zones", lambda r: ["zones", r], 0, {})])

    def deleted_sample():
        r = fx.copy_run("nosample")
        return fx.sql(r, "DELETE FROM samples WHERE rowid = (SELECT min(rowid) FROM samples)")
    store_case("a store with a deleted sample", deleted_sample, [("verify", lambda r: ["verify", r], 1, {})])

    def no_campaign():
        r = fx.copy_run("nocampaign")
        return fx.sql(r, "DELETE FROM campaign")
    # verify: job rows whose campaign was deleted are a finding about the store (exit 1, as a deleted sample), not a
    # refusal of the command; every other command refuses such a store
    store_case("a store without its campaign", no_campaign, all_cmds(2, 1, 2, 2, 2))

    def blob():
        r = fx.copy_run("blob")
        return fx.sql(r, "UPDATE jobs SET points = X'01020304' WHERE rowid = (SELECT min(rowid) FROM jobs WHERE "
                      "points IS NOT NULL)")
    store_case("a store with a 4-byte points blob", blob, [("merge", lambda r: ["merge", r, "--into",
                                                                                fx.fresh("merge")], (0, 2), {}),
                                                           ("verify", lambda r: ["verify", r], 1, {}),
                                                           ("zones", lambda r: ["zones", r], (0, 1, 2), {})])

    def packed():
        r = fx.T / "runs" / "packed"
        r.mkdir(parents=True, exist_ok=True)
        subprocess.run([sys.executable, "-c", "import sys; from pathlib import Path; "
                        "from vbl_robust.store import ResultStore; "
                        "from vbl_robust.store import pack_store; "
                        "s = ResultStore.open_existing(Path(sys.argv[1])); pack_store(s, Path(sys.argv[2]))",
                        str(run_), str(r / "results.sqlite.xz")], env=ENV, check=True, capture_output=True)
        return r
    store_case("a packed store", packed, [("report md", lambda r: ["report", r, "--format", "md"], (0, 2), {}),
                                         ("verify", lambda r: ["verify", r], (0, 2), {}),
                                         ("zones", lambda r: ["zones", r], (0, 2), {})])

    def bad_xz():
        r = fx.T / "runs" / "badxz"
        r.mkdir(parents=True, exist_ok=True)
        (r / "results.sqlite.xz").write_bytes(b"\xfd7zXZ\x00" + os.urandom(300))
        return r
    store_case("a damaged packed store", bad_xz, [("report md", lambda r: ["report", r, "--format", "md"], 2, {}),
                                                 ("verify", lambda r: ["verify", r], 2, {})])

    # --- report ---------------------------------------------------------------------------------------------------
    add("report run", ["report", run_, "--out", fx.fresh("rep")], 0, unchanged=(run_,))
    for fmt in ("md", "csv", "json"):
        add(f"report --format {fmt}", ["report", run_, "--format", fmt], 0, unchanged=(run_,),
            check=json_out if fmt == "json" else not_empty)
        add(f"report risk --format {fmt}", ["report", risk_, "--format", fmt], 0, unchanged=(risk_,),
            check=json_out if fmt == "json" else not_empty)
    add("report risk html", ["report", risk_, "--out", fx.fresh("rep")], 0, unchanged=(risk_,))
    add("report --format unknown", ["report", run_, "--format", "pdf"], 2, unchanged=(run_,))
    add("report --format empty", ["report", run_, "--format", ""], 2, unchanged=(run_,))
    add("report missing run", ["report", fx.T / "none"], 2)
    add("report of a dataset dir", ["report", fx.ds], 2, unchanged=(fx.ds,))
    add("report non-UTF-8 path", ["report", os.fsencode(str(fx.T)) + b"/\xff\xfe"], 2)
    add("report --compare missing", ["report", run_, "--compare", fx.T / "none", "--out", fx.fresh()], 2)
    add("report --compare risk run", ["report", run_, "--compare", risk_, "--out", o := fx.fresh()], 2)
    add("report --compare itself", ["report", run_, "--compare", run_, "--out", fx.fresh()], (0, 2))
    add("report --with missing", ["report", run_, "--format", "md", "--with", fx.T / "none"], 2)
    add("report --with a risk run", ["report", run_, "--format", "md", "--with", risk_], 2)
    add("report --csv under /proc", ["report", run_, "--format", "md", "--csv", "/proc/nope/x.csv"], 2)
    add("report --out is a file", ["report", run_, "--out", fx.plugin], 2, unchanged=(fx.plugin, run_))
    add("report --with on html", ["report", run_, "--with", run_, "--out", fx.fresh()], (0, 2))
    add("report hostile-named run escaped", ["report", hostile, "--out", o := fx.fresh()], 0,
        check=file_escaped(lambda o=o: [o / "report.html"]))

    # --- zones ----------------------------------------------------------------------------------------------------
    add("zones run", ["zones", run_], 0, check=json_out)
    for fmt in ("csv", "md"):
        add(f"zones --format {fmt}", ["zones", run_, "--format", fmt], 0, check=not_empty)
    add("zones --estimate", ["zones", run_, "--estimate", "--format", "md"], 0)
    add("zones --plot", ["zones", run_, "--plot", fx.fresh("plot")], 0)
    for name, extra in [("threshold -1", ["--threshold", "-1"]), ("threshold 0", ["--threshold", "0"]),
                        ("threshold nan", ["--threshold", "nan"]), ("threshold inf", ["--threshold", "inf"]),
                        ("threshold word", ["--threshold", "far"]), ("norm 3", ["--lipschitz", "1", "--norm", "3"]),
                        ("lipschitz negative", ["--lipschitz", "-1"]), ("lipschitz nan", ["--lipschitz", "nan"]),
                        ("lipschitz word", ["--lipschitz", "x"]), ("lipschitz two for 1-D", ["--lipschitz", "1,2"]),
                        ("lipschitz '5,'", ["--lipschitz", "5,"]),
                        ("format unknown", ["--format", "xml"]), ("role unknown", ["--role", "boss"]),
                        ("out under /proc", ["--out", "/proc/nope/z.json"]), ("plot is a file", ["--plot", fx.plugin])]:
        add(f"zones {name}", ["zones", run_, *extra], 2, unchanged=(run_, fx.plugin))
    add("zones of a risk run", ["zones", risk_], (0, 2), unchanged=(risk_,))
    add("zones missing run", ["zones", fx.T / "none"], 2)

    # --- verify ---------------------------------------------------------------------------------------------------
    add("verify run", ["verify", run_], 0, unchanged=(run_,))
    add("verify risk run", ["verify", risk_], 0, unchanged=(risk_,))
    add("verify --head wrong", ["verify", run_, "--head", "0" * 64], 1, unchanged=(run_,))
    add("verify --head garbage", ["verify", run_, "--head", SVG], (1, 2), unchanged=(run_,))
    add("verify --head empty", ["verify", run_, "--head", ""], (1, 2), unchanged=(run_,))
    add("verify missing run", ["verify", fx.T / "none"], 2)
    add("verify a file that is not a store", ["verify", fx.plugin], 2)

    # --- merge ----------------------------------------------------------------------------------------------------
    add("merge run into a new run", ["merge", run_, "--into", fx.T / "runs" / "merged"], 0, unchanged=(run_,))
    add("merge again (nothing new)", ["merge", run_, "--into", fx.T / "runs" / "merged"], 0, unchanged=(run_,))
    add("merge into itself", ["merge", run_, "--into", run_], 2, unchanged=(run_,))
    add("merge another campaign", ["merge", risk_, "--into", fx.T / "runs" / "merged"], 2,
        unchanged=(risk_, fx.T / "runs" / "merged"))
    add("merge missing source", ["merge", fx.T / "none", "--into", o := fx.fresh("merge")], 2, absent=(o,))
    add("merge no source", ["merge", "--into", o := fx.fresh("merge")], 2, absent=(o,))
    add("merge --into a file", ["merge", run_, "--into", fx.plugin], 2, unchanged=(fx.plugin,))
    add("merge --into /proc", ["merge", run_, "--into", "/proc/nope"], 2)

    # --- bundle ---------------------------------------------------------------------------------------------------
    b_root = fx.T / "broot"

    def mk_root():
        if not b_root.exists():
            b_root.mkdir()
            shutil.copytree(run_, b_root / "run")
            shutil.copytree(fx.T / "runs" / f"x|{SVG}", b_root / f"x|{SVG}") if hostile.exists() else None
        return b_root
    bo = fx.fresh("bundle")
    P.append(Probe("bundle a root with a hostile-named run (escaped)", [], 0, fn=_lazy_run(
        lambda: ["bundle", mk_root(), "--out", bo],
        file_escaped(lambda: [p for p in bo.rglob("*") if p.suffix in (".md", ".html")] or [bo / "index.html"]))))
    bs = fx.fresh("bundle")
    P.append(Probe("bundle --stores", [], 0, fn=_lazy_run(lambda: ["bundle", mk_root(), "--out", bs, "--stores"])))
    P.append(Probe("reproduce --resume-from a bundle with a stored factory", [], 2, marker=fx.marker,
                   fn=_lazy_run(lambda: ["reproduce", "spatial-1d", *rp, "--resume-from", _evil_bundle(fx),
                                         "--out", fx.fresh("repro")])))
    add("bundle missing root", ["bundle", fx.T / "none", "--out", o := fx.fresh("bundle")], 2, absent=(o,))
    add("bundle --out is a file", ["bundle", run_.parent, "--out", fx.plugin], 2, unchanged=(fx.plugin,))
    add("bundle --reproduction missing", ["bundle", run_.parent, "--out", o := fx.fresh("bundle"),
                                          "--reproduction", fx.T / "none.md"], 2, absent=(o,))
    f = fx.T / "repro_latin.md"
    f.write_bytes(b"<!-- bundle:begin -->\xff<!-- bundle:end -->\n")
    add("bundle --reproduction non-UTF-8", ["bundle", run_.parent, "--out", o := fx.fresh("bundle"),
                                            "--reproduction", f], 2, unchanged=(f,))
    f = fx.T / "repro_nomark.md"
    f.write_text("# no markers\n")
    add("bundle --reproduction without markers", ["bundle", run_.parent, "--out", fx.fresh("bundle"),
                                                  "--reproduction", f], (0, 2), unchanged=(f,))
    add("bundle of an empty dir", ["bundle", fx.T / "fresh", "--out", fx.fresh("bundle")], (0, 2))

    # --- check ----------------------------------------------------------------------------------------------------
    add("check dataset", ["check", fx.ds], 0, unchanged=(fx.ds,))
    add("check --all --json", ["check", fx.ds, "--all", "--json", fx.fresh("check.json")], 0)
    add("check missing", ["check", fx.T / "none"], 2)
    add("check a file", ["check", fx.plugin], 2)
    add("check a run dir", ["check", run_], 2, unchanged=(run_,))
    add("check --json under /proc", ["check", fx.ds, "--json", "/proc/nope/x.json"], 2)
    add("check --sequences on single images", ["check", fx.ds, "--sequences"], (0, 1, 2))
    for name, make, expect in [
        ("truncated JPEG", lambda: fx.ds_image_bytes("c_third", lambda b: b[: len(b) // 3]), 1),
        ("0-byte image", lambda: fx.ds_image_bytes("c_zero", lambda b: b""), 1),
        ("PNG claiming 30000x30000", lambda: fx.ds_image_bytes("c_huge", lambda b: png_header(30000, 30000)), 1),
        ("fifth corner", lambda: _fifth_corner(fx, "c_fifth"), (1, 2)),
        ("traversal", lambda: fx.ds_edit("c_trav", image="../../etc/passwd"), (1, 2)),
        ("markup image name", lambda: fx.ds_image_named("c_markup", f"a|b{SVG}.jpg"), 0),
    ]:
        P.append(Probe(f"check {name}", [], expect, fn=_lazy_run(lambda make=make: ["check", make()])))

    # --- scenes ---------------------------------------------------------------------------------------------------
    sc = ["--n", "1", "--width", "160", "--height", "160"]
    for name, extra in [("n 0", ["--n", "0"]), ("width 15", ["--width", "15"]), ("fov 0", ["--fov", "0"]),
                        ("fov negative", ["--fov", "-30"]), ("fov 180", ["--fov", "180"]), ("fov nan", ["--fov", "nan"]),
                        ("fov inf", ["--fov", "inf"]), ("envelopes unknown", ["--envelopes", "bogus"]),
                        ("envelopes empty", ["--envelopes", ""]), ("envelopes trailing comma", ["--envelopes", "A,"]),
                        ("speed negative", ["--sequences", "1", "--speed", "-1"]),
                        ("speed nan", ["--sequences", "1", "--speed", "nan"]),
                        ("rate 0", ["--sequences", "1", "--rate", "0"]), ("frames 0", ["--sequences", "1", "--frames", "0"]),
                        ("sequences 0", ["--sequences", "0"]), ("seed negative", ["--seed", "-1"])]:
        add(f"scenes {name}", ["scenes", *sc, *extra, "--out", o := fx.fresh("scenes")], 2, absent=(o,))
    add("scenes --out is a file", ["scenes", *sc, "--out", fx.plugin], 2, unchanged=(fx.plugin,))
    add("scenes --out missing", ["scenes", *sc], 2)
    add("scenes 16x16", ["scenes", "--n", "1", "--width", "16", "--height", "16", "--out", fx.fresh("scenes")], (0, 2))
    add("scenes into an existing dataset", ["scenes", *sc, "--out", fx.ds], (0, 2), unchanged=(fx.ds,))
    add("scenes hostile out name", ["scenes", *sc, "--out", fx.T / "fresh" / f"s|{SVG}"], 0)
    add("scenes tiny sequence", ["scenes", "--sequences", "1", "--frames", "2", "--width", "160", "--height", "160",
                                 "--out", fx.fresh("scenes")], 0)
    add("scenes 1x8192 strip", ["scenes", "--n", "1", "--width", "8192", "--height", "16",
                                "--out", fx.fresh("scenes")], (0, 2))

    # --- train / harden / ship: refusals only (never a real training run) -----------------------------------------
    tr = ["--n-train", "2", "--n-val", "1", "--epochs", "1", "--imgsz", "32", "--batch", "1"]
    for name, extra in [("imgsz 33", ["--imgsz", "33"]), ("imgsz 0", ["--imgsz", "0"]), ("n-train 1", ["--n-train", "1"]),
                        ("epochs 0", ["--epochs", "0"]), ("batch 0", ["--batch", "0"]),
                        ("init missing", ["--init", fx.T / "none.pt"]), ("init user pt untrusted", ["--init", fx.pt]),
                        ("init 0-byte pt trusted", ["--init", fx.T / "bad_0-byte.pt", "--trust-model"]),
                        ("lard missing", ["--lard", fx.T / "none"]), ("detector unknown", ["--detector", "x"]),
                        ("optimizer unknown", ["--optimizer", "Magic"]), ("arch unknown", ["--arch", "nope-pose"]),
                        ("lr0 negative", ["--lr0", "-1"]), ("lr0 nan", ["--lr0", "nan"]),
                        ("workers negative", ["--workers", "-1"])]:
        add(f"train {name}", ["train", *tr, *extra, "--out", o := fx.fresh("train")], 2, absent=(o,), timeout=90)
    hd = ["--perturb", "roll_deg=-5,5", "--rounds", "1", "--n-train", "1", "--n-val", "1", "--epochs", "1",
          "--imgsz", "32", "--k", "1"]
    for name, extra in [("perturb unknown", ["--perturb", "bogus=1,2"]), ("k 0", ["--k", "0"]),
                        ("rounds 0", ["--rounds", "0"]), ("model missing", ["--model", fx.T / "none.pt"]),
                        ("model user pt untrusted", ["--model", fx.pt]), ("imgsz 33", ["--imgsz", "33"]),
                        ("data unknown", ["--data", "imaginary"]), ("engine unknown", ["--engine", "x"]),
                        ("perturb '='", ["--perturb", "="])]:
        add(f"harden {name}", ["harden", *hd, *extra, "--out", o := fx.fresh("harden")], 2, absent=(o,), timeout=90)
    add("harden without --perturb", ["harden", "--out", o := fx.fresh("harden")], 2, absent=(o,))
    models_before = {}
    for name, args in [("checkpoint missing", [fx.T / "none.pt", "--epochs", "1", "--version", "9"]),
                       ("user pt untrusted", [fx.pt, "--epochs", "1", "--version", "9"]),
                       ("epochs missing", [fx.pt, "--version", "9", "--trust-model"]),
                       ("version 0", [fx.pt, "--epochs", "1", "--version", "0", "--trust-model"]),
                       ("as unknown", [fx.pt, "--epochs", "1", "--version", "9", "--trust-model", "--as", "x"]),
                       ("0-byte checkpoint", [fx.T / "bad_0-byte.pt", "--epochs", "1", "--version", "9",
                                              "--trust-model"]),
                       ("protocol missing", [fx.pt, "--epochs", "1", "--version", "9", "--trust-model",
                                             "--protocol", fx.T / "none.json"])]:
        add(f"ship {name}", ["ship", *args], 2, unchanged=(MODELS_DIR,), timeout=90)
    del models_before
    return P


# ---------------------------------------------------------------------------------------------------------------
# probe helpers needing the fixtures


def _lazy_run(argf: Callable[[], list], check: Callable | None = None) -> Callable[[], tuple]:
    def fn():
        res = run(argf())
        return res, (list(check(res) or []) if (check and res.rc is not None) else [])
    return fn


def _rm_first(fx: Fx, name: str) -> Path:
    d = fx.T / "data" / name
    _, rows = fx.rows(d)
    (d / rows[0]["image"]).unlink(missing_ok=True)
    return d


def _fifth_corner(fx: Fx, name: str = "fifth") -> Path:
    d = fx.copy_ds(name)
    db = d / "runways_db.json"
    data = json.loads(db.read_text())
    for airport in data.values():
        for runway in airport.values():
            runway["E"] = dict(runway["A"])
    db.write_text(json.dumps(data))
    return d


def _db_bytes(fx: Fx, name: str, data: bytes) -> Path:
    d = fx.copy_ds(name)
    (d / "runways_db.json").write_bytes(data)
    return d


def _csv_bytes(fx: Fx, name: str, edit: Callable[[bytes], bytes]) -> Path:
    d = fx.copy_ds(name)
    f = d / fx.csv_name
    f.write_bytes(edit(f.read_bytes()))
    return d


def _drop_column(fx: Fx, name: str, column: str) -> Path:
    d = fx.copy_ds(name)
    fields, rows = fx.rows(d)
    fields.remove(column)
    for r in rows:
        r.pop(column)
    fx.write_rows(d, fields, rows)
    return d


def _symlink_image(fx: Fx) -> Path:
    d = fx.copy_ds("symlink")
    _, rows = fx.rows(d)
    img = d / rows[0]["image"]
    outside = fx.T / "outside.jpg"
    shutil.copyfile(img, outside)
    img.unlink()
    img.symlink_to(outside)
    return d


def _latin_name(fx: Fx) -> Path:
    d = fx.copy_ds("latin")
    fields, rows = fx.rows(d)
    img = d / rows[0]["image"]
    new = os.fsencode(str(img.parent)) + b"/caf\xe9.jpg"
    os.rename(os.fsencode(str(img)), new)
    data = (d / fx.csv_name).read_bytes().replace(os.fsencode(rows[0]["image"]),
                                                  os.fsencode(str(Path(rows[0]["image"]).parent)) + b"/caf\xe9.jpg")
    (d / fx.csv_name).write_bytes(data)
    return d


def fx_meta(src: Path, dst: Path, key: str, value: str) -> None:
    import onnx  # the venv's; only when an export exists

    model = onnx.load(str(src))
    for prop in model.metadata_props:
        if prop.key == key:
            prop.value = value
    onnx.save(model, str(dst))


def _evil_bundle(fx: Fx) -> Path:
    """A bundle (``bundle --stores``) of a root whose run's campaign names subprocess:run."""
    root = fx.T / "evilroot"
    if not root.exists():
        root.mkdir()
        shutil.copytree(fx.evil("evil-b"), root / "spatial-1d")
    out = fx.T / "evilbundle"
    if not out.exists():
        res = run(["bundle", root, "--out", out, "--stores"])
        if not any(out.rglob("*.xz")):  # bundle refused the store itself: pack it by hand where it would lie
            (out / "spatial-1d").mkdir(parents=True, exist_ok=True)
            subprocess.run([sys.executable, "-c", "import lzma, sys, shutil; shutil.copyfileobj(open(sys.argv[1], 'rb'),"
                            " lzma.open(sys.argv[2], 'wb'))", str(root / "spatial-1d" / "results.sqlite"),
                            str(out / "spatial-1d" / "results.sqlite.xz")], check=True)
        del res
    return out


def _start(args: list) -> subprocess.Popen:
    return subprocess.Popen([VBL, *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, env=ENV, cwd=ROOT, start_new_session=True)


def _jobs_count(run: Path) -> int:
    try:
        con = sqlite3.connect(f"file:{run / 'results.sqlite'}?mode=ro", uri=True, timeout=1)
        try:
            return con.execute("SELECT count(*) FROM jobs WHERE status IS NOT NULL").fetchone()[0]
        finally:
            con.close()
    except sqlite3.Error:
        return 0


def _kill_rerun(fx: Fx, sig: int) -> tuple[Result, list]:
    """Start an audit, send ``sig`` once its first row is committed, check no worker outlives it, rerun; the rows
    must equal an uninterrupted run's (the reference, run once)."""
    args = ["audit", "--oracle", "--n", "4", "--max-evals", "1500", "--roll", "5", "--methods", "random,georobust-av",
            "--no-landscape", "--width", "160", "--height", "160", "-q", "--no-report"]
    ref = fx.T / "runs" / "kill-reference"
    found: list = []
    if not ref.exists():
        r = run([*args, "--out", ref], timeout=300)
        if r.rc != 0:
            return r, [("bad", f"the reference run failed ({r.rc})")]
        fx.ref_seconds = r.seconds
    out = fx.fresh("killed")
    p = _start([*args, "--out", out])
    t0 = time.monotonic()
    kids: set[int] = set()
    while p.poll() is None and time.monotonic() - t0 < 120:
        kids.update(children(p.pid))
        if _jobs_count(out) >= 1:
            break
        time.sleep(0.1)
    kids.update(children(p.pid))
    if p.poll() is not None:
        found.append(("weak", "the run ended before it could be interrupted"))
    else:
        os.kill(p.pid, sig)
    try:
        first, _ = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        first, _ = p.communicate()
        found.append(("bad", f"did not stop within 60 s of signal {sig}"))
    first = first.decode("utf-8", "replace")
    if "Traceback" in first:
        found.append(("bad", "traceback on the interrupt"))
    time.sleep(5)
    orphans = [k for k in kids if alive(k)]
    if orphans:
        found.append(("bad", f"{len(orphans)} worker(s) outlived the parent"))
        for k in orphans:
            try:
                os.kill(k, signal.SIGKILL)
            except OSError:
                pass
    rr = run([*args, "--out", out], timeout=300)
    if rr.rc == 0 and jobs_of(out) != jobs_of(ref):
        found.append(("bad", "the rerun's rows differ from the uninterrupted run's"))
    rr.cmd = f"{_show(['vbl-robust', *args])} --out X; kill -{signal.Signals(sig).name} at its first row; rerun"
    found.append(("ok", f"first exit {p.returncode}, {len(kids)} children"))
    return rr, [f for f in found if f[0] != "ok"] or []


def _live_store(fx: Fx) -> tuple[Result, list]:
    """While an audit writes its store: another audit on it is refused (exit 2, store unchanged by it), report /
    verify / zones read it without a traceback and report says it is unfinished; then kill -9 and rerun."""
    args = ["audit", "--oracle", "--n", "4", "--max-evals", "0", "--max-seconds", "8", "--roll", "5",
            "--methods", "random", "--no-landscape", "--width", "160", "--height", "160", "-q", "--no-report"]
    out = fx.fresh("live")
    p = _start([*args, "--out", out])
    found: list = []
    t0 = time.monotonic()
    while p.poll() is None and _jobs_count(out) < 1 and time.monotonic() - t0 < 120:
        time.sleep(0.2)
    if p.poll() is not None:
        found.append(("weak", "the run ended before the probes"))
    notes = []
    for label, a, expect in [("second writer", [*args, "--out", out], (2,)),
                             ("report md", ["report", out, "--format", "md"], (0, 1)),
                             ("verify", ["verify", out], (0,)), ("zones", ["zones", out], (0,)),
                             ("merge", ["merge", out, "--into", fx.fresh("merge")], (0, 2))]:
        r = run(a, timeout=60)
        notes.append(f"{label}: {r.rc}")
        if r.rc is None:
            found.append(("bad", f"{label} hung"))
        elif "Traceback" in r.out:
            found.append(("bad", f"{label}: traceback"))
        elif r.rc not in expect:
            found.append(("weak", f"{label}: exit {r.rc}"))
        if label == "report md" and r.rc == 0 and not any(w in r.out.lower() for w in
                                                          ("unfinished", "incomplete", "being written", "still", "to come",
                                                           "in progress", "not yet", "running")):
            found.append(("weak", "report on a live store does not say it is unfinished"))
    os.kill(p.pid, signal.SIGKILL)
    p.communicate()
    time.sleep(3)
    rr = run([*args, "--out", out], timeout=300)
    v = run(["verify", out])
    if v.rc != 0:
        found.append(("bad", f"verify after kill -9 and rerun: exit {v.rc}"))
    rr.cmd = "audit (8 s/job) writing; second writer, report, verify, zones, merge; kill -9; rerun; verify"
    rr.out += "\n" + ", ".join(notes)
    return rr, found


# ---------------------------------------------------------------------------------------------------------------


def cell(s: str, n: int = 160) -> str:
    s = " ".join(str(s).encode("utf-8", "backslashreplace").decode("utf-8").split())
    s = s if len(s) <= n else s[: n - 1] + "…"
    return s.replace("&", "&amp;").replace("|", "\\|").replace("<", "&lt;").replace(">", "&gt;")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help="write the Markdown table here (default: standard output)")
    ap.add_argument("--only", action="append", default=None,
                    help="run only the probes whose name contains this (repeatable: any of them)")
    ap.add_argument("--keep", action="store_true", help="keep the temporary directory (printed)")
    ap.add_argument("--start", type=int, default=1, help="begin at probe number START (1-based; to finish a run "
                    "cut short by --stop-after)")
    ap.add_argument("--stop-after", type=float, default=None,
                    help="start no probe after this many seconds (those left are counted as not run)")
    ns = ap.parse_args(argv)
    T = Path(tempfile.mkdtemp(prefix="vbl-probes-"))
    t_start = time.monotonic()
    try:
        fx = Fx(T)
        fx.build()
        fx.run_jobs = jobs_of(fx.run)
        ps = probes(fx)
        if ns.only:
            ps = [p for p in ps if any(w in p.name for w in ns.only)]
        first = ns.start
        ps = ps[first - 1:]
        outcomes, skipped = [], 0
        for i, p in enumerate(ps, first):
            if ns.stop_after is not None and time.monotonic() - t_start > ns.stop_after:
                skipped = len(ps) - (i - first)
                break
            o = run_probe(p)
            outcomes.append(o)
            print(f"[{i}/{len(ps) + first - 1}] {o.level:4s} {o.res.seconds:6.1f}s {p.name}" + (f" — {o.note}" if o.note else ""),
                  file=sys.stderr, flush=True)
    finally:
        if not ns.keep:
            shutil.rmtree(T, ignore_errors=True)
        else:
            print(f"fixtures kept in {T}", file=sys.stderr)
    counts = {lv: sum(o.level == lv for o in outcomes) for lv in LEVEL}

    def expect(e):
        return "/".join(map(str, e)) if isinstance(e, tuple) else str(e)
    lines = [f"# Adversarial probes of vbl-robust ({len(outcomes)} probes, default workers)", "",
             "Fixtures: " + "; ".join(fx.log), "",
             "| # | probe | command | expected | exit | outcome | note |", "|---|---|---|---|---|---|---|"]
    for i, o in enumerate(outcomes, first):
        cmd = o.res.cmd.replace(str(T), "$T")
        note = o.note.replace(str(T), "$T")
        lines.append(f"| {i} | {cell(o.probe.name, 90)} | `{cell(cmd, 200)}` | {expect(o.probe.expect)} | "
                     f"{'timeout' if o.res.rc is None else o.res.rc} | **{o.level}** | {cell(note, 200)} |")
    summary = (f"{len(outcomes)} probes: {counts['ok']} ok, {counts['weak']} weak, {counts['bad']} bad "
               f"({time.monotonic() - t_start:.0f} s)" + (f"; {skipped} not run (--stop-after)" if skipped else ""))
    lines += ["", summary, ""]
    text = "\n".join(lines)
    if ns.out:
        ns.out.write_text(text, encoding="utf-8", errors="backslashreplace")  # a probe's non-UTF-8 name
    else:
        print(text)
    print(summary, file=sys.stderr)
    return 1 if counts["bad"] else 0


if __name__ == "__main__":
    sys.exit(main())
