"""Run a campaign: expand the spec, skip what the store already holds, execute the rest, commit job by job.

Executors:

- ``"local"`` (default): with ``workers=1`` the jobs run in this process, sample after sample, the detector built
  once; with ``workers=N > 1`` in N worker processes (one torch thread each, one sample at a time each, the
  detector built once per worker; :func:`_pool_rows`), whose rows this process alone writes into the store.
  :func:`default_workers` = the machine's cores (``VBL_ROBUST_WORKERS`` overrides it).
- ``"ray"``: one Ray task per sample (a streaming generator: each finished job's rows come back as soon as they
  are ready); workers build the detector once each; this process writes every row into the same store.
  ``address`` = an existing cluster (``"auto"``, ``"host:6379"``; Ray Client ``ray://`` is refused), else a local Ray instance is started.

Progress goes through a callback receiving :class:`Progress` after every committed job; the CLI renders it.
"""

from __future__ import annotations

import logging
import os
import platform
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from ..constants import Verdict
from ..specs.campaign import CampaignSpec, Job
from ..specs.kinds import Role, RunStatus
from ..specs.settings import PipelineSettings
from ..store.core import ResultStore
from ..store.lock import WriterLock
from ..store.rows import JobRow, RunProvenance, SampleRecord
from .precheck import check_run
from .provenance import (
    DetectorSpec,
    code_version,
    dataset_identity,
    library_versions,
    machine_identity,
    sample_fingerprint,
)
from .work import SampleTask, detector_for, one_core, run_sample_task

logger = logging.getLogger(__name__)

EXECUTORS = ("local", "ray")
#: Environment variable that sets :func:`default_workers` (e.g. 1 on a machine shared with other work).
WORKERS_ENV = "VBL_ROBUST_WORKERS"


def default_workers() -> int:
    """Worker processes of a local campaign by default: ``$VBL_ROBUST_WORKERS`` if set, else the cores this
    process may use."""
    env = os.environ.get(WORKERS_ENV, "").strip()
    if env:
        if not env.isdigit() or int(env) < 1:
            raise ValueError(f"{WORKERS_ENV} must be an integer >= 1, got {env!r}")
        return int(env)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


@dataclass(frozen=True)
class Progress:
    """State after a committed job. ``done`` counts jobs finished in earlier runs too (``skipped``)."""

    done: int
    total: int
    skipped: int
    breaches: int
    not_measured: int
    elapsed: float
    last: JobRow | None = None


@dataclass(frozen=True)
class RunSummary:
    run_id: int
    total: int
    skipped: int
    done: int
    not_measured: int
    breaches: int
    seconds: float
    status: RunStatus


#: Seconds to wait for a Ray cluster's address to accept a connection before a run is refused.
RAY_CONNECT_TIMEOUT_S = 10.0


def check_executor(executor: str, address: str | None, *, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """``ValueError`` (one line naming the option) before any work: an unknown executor, ``address`` without Ray,
    or a Ray address (``host:port`` of the head's GCS, or ``auto``: Ray's own lookup of a cluster started on this
    machine) where no gRPC server completes a handshake within ``timeout_s``. Ray's services speak gRPC over HTTP/2:
    a port that merely accepts TCP (another service, a silent socket) never completes the HTTP/2 handshake and is
    refused here, where Ray itself would retry for minutes. A cluster with token authentication is then joined as
    :func:`join_ray_auth` says (it may set ``RAY_AUTH_MODE=token`` here). A Ray Client address (``ray://``) is
    refused: the runner streams each sample's rows back with Ray generators, which Ray Client does not carry."""
    import socket
    from urllib.parse import urlsplit

    if executor not in EXECUTORS:
        raise ValueError(f"--executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
    if address is None:
        return
    if executor != "ray":
        raise ValueError(f"--address {address} applies to --executor ray only")
    target = _running_cluster() if address == "auto" else address
    if target is None:
        raise ValueError("--address auto: no Ray cluster is running on this machine (start one with `ray start "
                         "--head`, or name its address)")
    parts = urlsplit(target if "://" in target else f"ray://{target}")
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        host, port = None, None
    if not host or port is None:
        raise ValueError(f"--address {address}: expected host:port (or auto)")
    if "://" in target:
        raise ValueError(f"--address {address}: Ray Client addresses are not supported (runs stream their rows back "
                         f"with Ray generators, which Ray Client does not carry): run on a machine of the cluster "
                         f"with --address auto or the head's host:port")
    try:  # a closed port is refused at once; an open one must then speak gRPC
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as exc:
        raise ValueError(f"--address {address}: no Ray cluster answers at {host}:{port} within {timeout_s:g} s "
                         f"({exc.strerror or exc})") from None
    if not grpc_answers(host, port, timeout_s):
        raise ValueError(f"--address {address}: no Ray cluster answers at {host}:{port} within {timeout_s:g} s "
                         f"(the port is open but completes no gRPC handshake: not a Ray service)")
    join_ray_auth(address, host, port, timeout_s)


#: Ray's token authentication (on by default since Ray 2.5x): the mode, and where Ray reads the token from, in
#: Ray's order — the variable's value, else the file the path variable names, else ``~/.ray/auth_token``.
RAY_AUTH_MODE_ENV = "RAY_AUTH_MODE"
RAY_AUTH_TOKEN_ENV = "RAY_AUTH_TOKEN"
RAY_AUTH_TOKEN_PATH_ENV = "RAY_AUTH_TOKEN_PATH"


def ray_auth_token() -> tuple[str | None, str]:
    """``(token, where it comes from)`` as Ray itself looks for it: ``$RAY_AUTH_TOKEN`` if set (a blank value is no
    token), else the file ``$RAY_AUTH_TOKEN_PATH`` names (unreadable or empty: no token, and no fall-back), else
    ``~/.ray/auth_token``; surrounding white space stripped. ``(None, why)`` when there is none."""
    from pathlib import Path

    value = os.environ.get(RAY_AUTH_TOKEN_ENV, "")
    if value:
        return value.strip() or None, RAY_AUTH_TOKEN_ENV
    named = os.environ.get(RAY_AUTH_TOKEN_PATH_ENV, "")
    path = Path(named) if named else Path(os.environ.get("HOME") or Path.home()) / ".ray" / "auth_token"
    try:
        token = path.read_text().strip()
    except (OSError, UnicodeDecodeError):
        token = ""
    if named:
        return (token, f"{RAY_AUTH_TOKEN_PATH_ENV}={named}") if token else (
            None, f"{RAY_AUTH_TOKEN_PATH_ENV}={named} cannot be read or is empty")
    return (token, str(path)) if token else (None, f"{RAY_AUTH_TOKEN_ENV} is not set and there is no {path}")


#: A harmless call on a Ray cluster's GCS (the address ``ray start`` prints): it reads the cluster's id, and a
#: cluster with token authentication refuses it UNAUTHENTICATED when the token is missing or wrong.
_RAY_AUTH_PROBE = "/ray.rpc.NodeInfoGcsService/GetClusterId"


def ray_rejects(host: str, port: int, token: str | None, timeout_s: float) -> bool:
    """Whether the Ray GCS at ``host:port`` refuses a call carrying ``token`` (None: no token) as unauthenticated;
    any other answer (success, an unknown method, a time-out) is no refusal."""
    import grpc

    metadata = (("authorization", f"Bearer {token}"),) if token else None
    with grpc.insecure_channel(f"{host}:{port}") as channel:
        try:
            channel.unary_unary(_RAY_AUTH_PROBE)(b"", timeout=timeout_s, metadata=metadata)
        except grpc.RpcError as exc:
            return exc.code() == grpc.StatusCode.UNAUTHENTICATED
    return False


def join_ray_auth(address: str, host: str, port: int, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """Make this process able to join the Ray cluster at ``host:port`` or say in one line (``ValueError``) why it
    cannot, before Ray's own connection retries (a screen of warnings, then "Failed to connect"). A cluster without
    token authentication needs nothing. One with it (``ray start --head`` turns it on when a token exists) needs
    the head's token here, found as Ray finds it (:func:`ray_auth_token`), and ``RAY_AUTH_MODE=token``: set here for
    this process when the user left it unset; its workers are started by the cluster's nodes, whose own
    ``RAY_AUTH_MODE`` counts. Refused: ``RAY_AUTH_MODE`` set to another mode, no token, a token the cluster rejects;
    and ``RAY_AUTH_MODE=token`` without a token (Ray refuses to connect then, even to a cluster without tokens)."""
    mode = os.environ.get(RAY_AUTH_MODE_ENV, "").strip()
    if not ray_rejects(host, port, None, timeout_s):
        token, source = ray_auth_token() if mode.lower() == "token" else ("", "")
        if token is None:
            raise ValueError(f"--address {address}: {RAY_AUTH_MODE_ENV}=token and no token was found ({source}); "
                             f"the cluster uses no token authentication: unset {RAY_AUTH_MODE_ENV}")
        return
    if mode and mode.lower() != "token":
        raise ValueError(f"--address {address}: the cluster uses token authentication but {RAY_AUTH_MODE_ENV}={mode}: "
                         f"unset it or set {RAY_AUTH_MODE_ENV}=token")
    token, source = ray_auth_token()
    if token is None:
        raise ValueError(f"--address {address}: the cluster uses token authentication and no token was found "
                         f"({source}): set {RAY_AUTH_TOKEN_ENV} to the head's token (`ray get-auth-token` on the "
                         f"head prints it) or copy the head's ~/.ray/auth_token here")
    if ray_rejects(host, port, token, timeout_s):
        raise ValueError(f"--address {address}: the cluster rejects the token from {source}: use the head's token "
                         f"(`ray get-auth-token` on the head prints it)")
    logger.info("Ray cluster at %s:%d: token authentication, token from %s accepted", host, port, source)
    if mode.lower() != "token":
        logger.info("%s=token set for this process (it was unset)", RAY_AUTH_MODE_ENV)
        os.environ[RAY_AUTH_MODE_ENV] = "token"
        try:  # Ray caches the mode it read at start-up: read it again, as Ray's own `ray start` does
            from ray._raylet import AuthenticationTokenLoader, Config

            Config.initialize("")
            AuthenticationTokenLoader.instance().reset_cache()
        except (ImportError, AttributeError):  # pragma: no cover - another Ray layout reads the variable anyway
            pass


def _running_cluster() -> str | None:
    """The address of the Ray cluster started on this machine (Ray's lookup behind ``address="auto"``), or None."""
    from ray._private.services import canonicalize_bootstrap_address

    try:
        return canonicalize_bootstrap_address("auto")
    except (ConnectionError, ValueError):
        return None


def grpc_answers(host: str, port: int, timeout_s: float) -> bool:
    """Whether a gRPC server at ``host:port`` completes the HTTP/2 handshake within ``timeout_s`` (a channel that
    becomes ready); a closed port, a non-gRPC service or a socket that never answers all give False."""
    import grpc

    channel = grpc.insecure_channel(f"{host}:{port}")
    try:
        grpc.channel_ready_future(channel).result(timeout=timeout_s)
        return True
    except grpc.FutureTimeoutError:
        return False
    finally:
        channel.close()


def sample_record(sample: Any, index: int) -> SampleRecord:
    """The store's record of ``sample``, the ``index``-th of the run."""
    import json

    meta = {k: v for k, v in (sample.meta or {}).items() if isinstance(v, str | int | float | bool)}
    return SampleRecord(sample.id, index, float(sample.slant_distance_m), (sample.meta or {}).get("envelope"),
                        int(sample.width), int(sample.height), sample_fingerprint(sample),
                        json.dumps(meta, sort_keys=True, default=str))


def plan(spec: CampaignSpec, samples: Sequence[Any], detector: DetectorSpec) -> list[Job]:
    """All jobs of ``spec`` on ``samples`` for ``detector`` (keys depend on all three)."""
    return spec.expand([(s.id, sample_fingerprint(s)) for s in samples], detector_id=detector.key())


def run_campaign(
    spec: CampaignSpec,
    samples: Sequence[Any],
    store: ResultStore,
    *,
    detector: DetectorSpec,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    ray_num_cpus: int | None = None,
    progress: Callable[[Progress], None] | None = None,
    dataset_source: dict[str, Any] | None = None,
    config: dict[str, Any] | None = None,
    wait: bool = False,
    retry_failed: bool = False,
    precheck: bool = True,
) -> RunSummary:
    """Run every job of ``spec`` on ``samples`` that ``store`` does not hold yet.

    Args:
        spec: the campaign.
        samples: the samples (ids unique).
        store: where rows go; bound to this campaign and detector (refused when it already holds job rows of
            another one; a store with no job row yet, e.g. after a run that failed on its detector, is re-bound).
        detector: how to build the detector (its identity is part of every job key).
        executor: "local" or "ray"; ``address``/``ray_num_cpus`` for Ray.
        workers: local executor: worker processes (1 = this process; the worker count is in the run's
            provenance).
        progress: called after every committed job.
        dataset_source: where the samples came from (provenance), e.g. ``{"kind": "synthetic", "n": 10, "seed": 0}``.
        config: the full user configuration (provenance; e.g. the CLI options).
        retry_failed: run the jobs stored as not measured again (e.g. after a missing image was restored); by default
            a rerun skips them like every stored job.
        precheck: check before anything is stored that every image can be read at its stated size and every method
            can run on the detector (:func:`~vbl_robust.campaigns.precheck.check_run`; ``ValueError``, one line);
            False only for a caller that has just checked.
        wait: when another process is writing ``store`` (:class:`~vbl_robust.store.lock.WriterLock`), wait
            for it instead of refusing (``ValueError`` naming its PID).
    """
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {EXECUTORS}, got {executor!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    spec.check()
    spec.check_samples(samples)
    if precheck:
        check_run(spec, samples, detector)  # every image readable, every method fit for the detector
    lock = WriterLock(store.path).acquire(wait=wait)
    try:
        return _run(spec, samples, store, detector, executor, workers, address, ray_num_cpus, progress,
                    dataset_source, config, retry_failed)
    finally:
        lock.release()


def _run(spec: CampaignSpec, samples: Sequence[Any], store: ResultStore, detector: DetectorSpec, executor: str,
         workers: int, address: str | None, ray_num_cpus: int | None, progress: Callable[[Progress], None] | None,
         dataset_source: dict[str, Any] | None, config: dict[str, Any] | None, retry_failed: bool = False,
         ) -> RunSummary:
    t0 = time.perf_counter()
    det_identity = detector.identity()
    store.bind_campaign(spec.name, spec.to_dict(), det_identity)
    jobs = plan(spec, samples, detector)
    store.check_contents(samples)
    if retry_failed:  # only once the store has accepted these settings and pixels: a refusal loses nothing
        logger.info("%d failed job(s) forgotten, to be run again", store.forget_failed())
    store.add_samples(sample_record(s, i) for i, s in enumerate(samples))
    done_keys = store.done_keys()
    pending = [j for j in jobs if j.key not in done_keys]
    skipped = len(jobs) - len(pending)
    dataset = dataset_identity(samples, dataset_source or {})
    run_id = store.begin_run(RunProvenance(
        code_version=code_version(), model_sha256=det_identity["sha256"], detector=det_identity,
        dataset_id=dataset["sha256"], dataset=dataset, seed=spec.seed, executor=executor,
        config={"campaign": spec.to_dict(), "user": config or {}, "executor": executor, "address": address,
                "workers": workers if executor == "local" else None, "clock": spec.settings.clock,
                "libraries": library_versions(), "machine": machine_identity()},
        host=platform.node(), jobs_total=len(jobs), jobs_skipped=skipped,
    ))
    logger.info("campaign %s: %d jobs, %d already done, %d to run (%s executor)", spec.name, len(jobs), skipped,
                len(pending), executor)

    by_sample: dict[str, list[Job]] = {}
    for j in pending:
        by_sample.setdefault(j.sample_id, []).append(j)
    sample_of = {s.id: s for s in samples}
    tasks = [SampleTask(sample_of[sid], js) for sid, js in by_sample.items()]
    settings = spec.settings

    state = {"new": 0, "not_measured": 0, "breaches": _stored_breaches(store)}

    def on_rows(rows: list[JobRow]) -> None:
        store.commit(rows)
        state["new"] += len(rows)
        state["not_measured"] += sum(not r.measured for r in rows)
        state["breaches"] += sum(r.verdict == Verdict.BREACH and r.role == Role.MAIN for r in rows)
        if progress is not None:
            progress(Progress(skipped + state["new"], len(jobs), skipped, state["breaches"], state["not_measured"],
                              time.perf_counter() - t0, rows[0]))

    if progress is not None:
        progress(Progress(skipped, len(jobs), skipped, state["breaches"], 0, 0.0, None))
    status = RunStatus.FINISHED
    try:
        if executor == "local" and (workers == 1 or len(tasks) <= 1):
            det = detector_for(detector) if tasks else None
            for task in tasks:
                for rows in run_sample_task(task, det, settings, run_id):
                    on_rows(rows)
        elif executor == "local":
            for rows in _pool_rows(tasks, detector, settings, run_id, min(workers, len(tasks))):
                on_rows(rows)
        else:
            for rows in _ray_rows(tasks, detector, settings, run_id, address, ray_num_cpus):
                on_rows(rows)
    except BaseException:
        status = RunStatus.INTERRUPTED
        raise
    finally:
        seconds = time.perf_counter() - t0
        if status == RunStatus.FINISHED and skipped + state["new"] < len(jobs):
            status = RunStatus.INCOMPLETE
        store.end_run(run_id, status, state["new"], seconds)
    return RunSummary(run_id, len(jobs), skipped, state["new"], state["not_measured"], state["breaches"], seconds,
                      status)


def _stored_breaches(store: ResultStore) -> int:
    return sum(r.verdict == Verdict.BREACH for r in store.jobs(role="main", with_trace=False))


# -- worker processes ---------------------------------------------------------------------------------------------
def _pool_rows(tasks: Sequence[SampleTask], detector: DetectorSpec, settings: PipelineSettings, run_id: int,
               workers: int) -> Iterator[list[JobRow]]:
    """Run the sample tasks in ``workers`` processes (spawned: a fresh interpreter each) and yield their rows in
    completion order. A worker that dies leaves its sample's unfinished jobs pending (a rerun resumes them)."""
    import multiprocessing as mp
    import pickle
    import queue

    from .pool_start import Message, start_worker

    ctx = mp.get_context("spawn")
    task_q, result_q = ctx.Queue(), ctx.Queue()
    for t in tasks:
        if hasattr(t.sample, "drop_pixels"):
            t.sample.drop_pixels()  # ship geometry and the loader, not megabytes of pixels
        task_q.put(t)
    for _ in range(workers):
        task_q.put(None)
    # the worker's own arguments travel as bytes, unpickled only once it is tied to this process (pool_start)
    payload = pickle.dumps((detector, settings, run_id))
    procs = [ctx.Process(target=start_worker, args=(os.getpid(), task_q, result_q, payload), daemon=True)
             for _ in range(workers)]
    for p in procs:
        p.start()
    left, errors = len(tasks), []
    try:
        while left:
            try:
                message, rows = result_q.get(timeout=1.0)
            except queue.Empty:
                if not any(p.is_alive() for p in procs):
                    why = f" (a worker could not start: {errors[0]})" if errors else ""
                    logger.error("every worker process ended with %d sample(s) unfinished%s; their jobs stay "
                                 "pending (rerun to resume)", left, why)
                    return
                continue
            if message is Message.DONE:
                left -= 1
            elif message is Message.ERROR:
                errors.append(rows)
            else:
                yield rows
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
            p.join(timeout=5)
        for q in (task_q, result_q):  # items no worker will read must not hold this process at exit
            q.cancel_join_thread()
            q.close()


# -- Ray -------------------------------------------------------------------------------------------------------
def _ray_sample_task(task: SampleTask, detector: DetectorSpec, settings: PipelineSettings, run_id: int) -> Iterator[list[JobRow]]:
    """Body of a Ray task: the same code as the local executor, in a worker (one core, as its task asks of Ray;
    detector cached per worker)."""
    one_core()
    yield from run_sample_task(task, detector_for(detector), settings, run_id)


def _ray_rows(tasks: Sequence[SampleTask], detector: DetectorSpec, settings: PipelineSettings, run_id: int,
              address: str | None, num_cpus: int | None) -> Iterator[list[JobRow]]:
    """Submit one streaming task per sample and yield rows as they arrive (in completion order)."""
    if not tasks:
        return
    try:
        import ray
    except ImportError as exc:  # pragma: no cover - ray is a dependency
        raise ValueError("--executor ray needs the 'ray' package (pip install 'ray[default]')") from exc
    started = False
    if not ray.is_initialized():
        kw: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
        if address:
            check_executor("ray", address)  # answers, and token authentication joined, before Ray's own retries
            try:
                ray.init(address=address, **kw)
            except ConnectionError as exc:  # e.g. --address auto with no cluster running: one line, not a trace
                raise ValueError(f"--address {address}: {str(exc).splitlines()[0]}") from None
        else:
            ray.init(num_cpus=num_cpus, **kw)
        started = True
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(_ray_sample_task)
        for s in (t.sample for t in tasks):
            if hasattr(s, "drop_pixels"):
                s.drop_pixels()  # ship geometry and the loader, not megabytes of pixels
        gens = [remote.remote(t, detector, settings, run_id) for t in tasks]
        pending = list(gens)
        while pending:
            ready, _ = ray.wait(pending, num_returns=1)
            for gen in ready:
                try:
                    ref = next(gen)
                except StopIteration:
                    pending.remove(gen)
                    continue
                try:
                    yield ray.get(ref)
                except Exception as exc:  # a crashed worker: its unfinished jobs stay pending for a rerun
                    logger.error("a Ray task failed; its remaining jobs stay pending (rerun to resume): %s", exc)
                    pending.remove(gen)
    finally:
        if started:
            ray.shutdown()
