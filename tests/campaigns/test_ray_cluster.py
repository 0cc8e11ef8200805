"""Joining a Ray cluster started the way users start one: ``ray start --head`` (token authentication on, as Ray
turns it on when a token exists) and a second node with ``ray start --address``; then ``vbl-robust audit
--executor ray --address HOST:PORT`` without ``RAY_AUTH_MODE`` in its environment. A missing or wrong token, or
``RAY_AUTH_MODE=disabled``, is refused in one line before any work.

The real cluster lives in its own ``--temp-dir``, ``HOME`` (where ``ray get-auth-token --generate`` writes the
token) and ports, each ``ray start`` in its own session: the cleanup ends the processes of those sessions only
(``ray stop`` would end every Ray process on the machine)."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import grpc
import pytest
from typer.testing import CliRunner

from vbl_robust.campaigns.runner import (
    RAY_AUTH_MODE_ENV,
    RAY_AUTH_TOKEN_ENV,
    RAY_AUTH_TOKEN_PATH_ENV,
    join_ray_auth,
    ray_auth_token,
    ray_rejects,
)
from vbl_robust.cli import app
from vbl_robust.store.core import ResultStore

#: The ``ray`` command of this environment (installed with the package), else the one on PATH.
RAY_CLI = next((Path(p) for p in (Path(sys.executable).with_name("ray"), shutil.which("ray")) if p and Path(p).exists()),
               None)
AUTH_VARS = (RAY_AUTH_MODE_ENV, RAY_AUTH_TOKEN_ENV, RAY_AUTH_TOKEN_PATH_ENV, "RAY_ADDRESS")
SMALL_AUDIT = ["audit", "--n", "2", "--roll", "5", "--methods", "random", "--max-evals", "6", "--no-landscape",
               "--no-report", "--oracle", "--oracle-noise", "0.5", "--width", "128", "--height", "128", "--quiet",
               "--executor", "ray"]


@pytest.fixture
def auth_env(tmp_path):
    """No Ray authentication variables and an empty ``HOME`` (no ``~/.ray/auth_token``): the test sets them in
    ``os.environ`` as it needs, the code under test may set ``RAY_AUTH_MODE``; all are restored afterwards, and
    Ray's cached view of them with them (a later ``ray.init`` in this process must see the environment it has)."""
    from ray._raylet import AuthenticationTokenLoader, Config

    saved = {var: os.environ.get(var) for var in (*AUTH_VARS, "HOME")}
    for var in AUTH_VARS:
        os.environ.pop(var, None)
    home = tmp_path / "home"
    home.mkdir()
    os.environ["HOME"] = str(home)
    try:
        yield home
    finally:
        for var, value in saved.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value
        Config.initialize("")
        AuthenticationTokenLoader.instance().reset_cache()


# -- the token as Ray finds it, and the handshake against a stand-in GCS -----------------------------------------
def test_the_token_is_found_where_and_as_ray_finds_it(auth_env, tmp_path):
    from ray._raylet import AuthenticationTokenLoader

    def ray_finds() -> str | None:
        loader = AuthenticationTokenLoader.instance()
        loader.reset_cache()
        try:
            return loader.get_raw_token(ignore_auth_mode=True) if loader.has_token(ignore_auth_mode=True) else None
        except Exception:  # Ray raises for a RAY_AUTH_TOKEN_PATH it cannot read
            return None

    (auth_env / ".ray").mkdir()
    named = tmp_path / "named-token"
    named.write_text("  from-path\n")
    cases = [({}, None),
             ({"home": "from-home\n"}, "from-home"),
             ({"home": "from-home", RAY_AUTH_TOKEN_ENV: " from-env "}, "from-env"),
             ({"home": "from-home", RAY_AUTH_TOKEN_ENV: "   "}, None),  # a blank token is no token, no fall-back
             ({"home": "from-home", RAY_AUTH_TOKEN_PATH_ENV: str(named)}, "from-path"),
             ({"home": "from-home", RAY_AUTH_TOKEN_PATH_ENV: str(tmp_path / "absent")}, None),  # no fall-back
             ({"home": "from-home", RAY_AUTH_TOKEN_ENV: "from-env", RAY_AUTH_TOKEN_PATH_ENV: str(named)}, "from-env")]
    for setting, expected in cases:
        home_file = auth_env / ".ray" / "auth_token"
        home_file.unlink(missing_ok=True)
        if "home" in setting:
            home_file.write_text(setting["home"])
        for var in (RAY_AUTH_TOKEN_ENV, RAY_AUTH_TOKEN_PATH_ENV):
            os.environ.pop(var, None)
            if var in setting:
                os.environ[var] = setting[var]
        token, source = ray_auth_token()
        assert (token, ray_finds()) == (expected, expected), (setting, source)


@pytest.fixture
def token_gcs():
    """A stand-in for a GCS with token authentication: the method the check calls, UNAUTHENTICATED unless the
    call carries ``Bearer right``."""
    def get_cluster_id(request, context):
        if ("authorization", "Bearer right") not in context.invocation_metadata():
            context.abort(grpc.StatusCode.UNAUTHENTICATED, "InvalidAuthToken: Authentication token is missing")
        return b""

    handler = grpc.method_handlers_generic_handler("ray.rpc.NodeInfoGcsService", {
        "GetClusterId": grpc.unary_unary_rpc_method_handler(get_cluster_id)})
    server = grpc.server(ThreadPoolExecutor(2), handlers=(handler,))
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        yield port
    finally:
        server.stop(None)


def test_a_cluster_with_token_authentication_is_joined_or_refused_in_one_line(auth_env, token_gcs):
    address = f"127.0.0.1:{token_gcs}"
    assert ray_rejects("127.0.0.1", token_gcs, None, 5.0) and not ray_rejects("127.0.0.1", token_gcs, "right", 5.0)
    with pytest.raises(ValueError, match=f"^--address {address}: the cluster uses token authentication and no "
                                         f"token was found .*set RAY_AUTH_TOKEN"):
        join_ray_auth(address, "127.0.0.1", token_gcs, 5.0)
    os.environ[RAY_AUTH_TOKEN_ENV] = "wrong"
    with pytest.raises(ValueError, match="the cluster rejects the token from RAY_AUTH_TOKEN"):
        join_ray_auth(address, "127.0.0.1", token_gcs, 5.0)
    (auth_env / ".ray").mkdir()
    (auth_env / ".ray" / "auth_token").write_text("right\n")
    del os.environ[RAY_AUTH_TOKEN_ENV]
    os.environ[RAY_AUTH_MODE_ENV] = "disabled"  # the user's explicit mode is kept, and refused here
    with pytest.raises(ValueError, match="token authentication but RAY_AUTH_MODE=disabled: unset it"):
        join_ray_auth(address, "127.0.0.1", token_gcs, 5.0)
    del os.environ[RAY_AUTH_MODE_ENV]
    join_ray_auth(address, "127.0.0.1", token_gcs, 5.0)  # the head's token in ~/.ray/auth_token: mode set here
    assert os.environ[RAY_AUTH_MODE_ENV] == "token"


def test_a_cluster_without_token_authentication_changes_nothing(auth_env):
    server = grpc.server(ThreadPoolExecutor(1))  # answers every call UNIMPLEMENTED, none UNAUTHENTICATED
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        join_ray_auth(f"127.0.0.1:{port}", "127.0.0.1", port, 5.0)
        assert RAY_AUTH_MODE_ENV not in os.environ
        os.environ[RAY_AUTH_MODE_ENV] = "token"  # Ray would refuse to connect without a token, even here
        with pytest.raises(ValueError, match="RAY_AUTH_MODE=token and no token was found .* unset RAY_AUTH_MODE"):
            join_ray_auth(f"127.0.0.1:{port}", "127.0.0.1", port, 5.0)
        os.environ[RAY_AUTH_TOKEN_ENV] = "any"
        join_ray_auth(f"127.0.0.1:{port}", "127.0.0.1", port, 5.0)
    finally:
        server.stop(None)


# -- a real two-node cluster ---------------------------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """Ray processes started with ``ray start``, each call in a session of its own (``start_new_session``); Ray's
    daemons stay in the session of the ``ray start`` that launched them, so :meth:`stop` can end exactly these."""

    def __init__(self, root: Path):
        self.root = root
        self.env = {k: v for k, v in os.environ.items() if k not in AUTH_VARS}
        self.env.update(HOME=str(root / "home"), RAY_USAGE_STATS_ENABLED="0", OMP_NUM_THREADS="1")
        self.sessions: list[int] = []
        self.port = _free_port()
        self.token = ""

    def ray(self, *args: str, env: dict[str, str] | None = None, timeout: float = 120) -> str:
        proc = subprocess.Popen([str(RAY_CLI), *args], env=env or self.env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self.sessions.append(proc.pid)
        try:
            out, _ = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
            raise AssertionError(f"ray {' '.join(args)} took over {timeout:g} s:\n{out[-3000:]}") from None
        assert proc.returncode == 0, f"ray {' '.join(args)} exited {proc.returncode}:\n{out[-3000:]}"
        return out

    def start_node(self, *args: str, env: dict[str, str] | None = None) -> str:
        # Own ports where Ray has fixed defaults, so that clusters of other runs on this machine do not collide
        return self.ray("start", "--num-cpus", "1", "--temp-dir", str(self.root / "ray"), "--disable-usage-stats",
                        "--dashboard-agent-listen-port", str(_free_port()), *args, env=env)

    def alive_nodes(self, token: str) -> int:
        from ray.core.generated import gcs_pb2, gcs_service_pb2, gcs_service_pb2_grpc

        with grpc.insecure_channel(f"127.0.0.1:{self.port}") as channel:
            reply = gcs_service_pb2_grpc.NodeInfoGcsServiceStub(channel).GetAllNodeInfo(
                gcs_service_pb2.GetAllNodeInfoRequest(), timeout=10, metadata=(("authorization", f"Bearer {token}"),))
        return sum(n.state == gcs_pb2.GcsNodeInfo.ALIVE for n in reply.node_info_list)

    def _pids(self) -> list[int]:
        pids = []
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit() and int(entry.name) != os.getpid():
                try:
                    if os.getsid(int(entry.name)) in self.sessions and "Z" not in _state(entry):
                        pids.append(int(entry.name))
                except (OSError, ValueError):
                    pass
        return pids

    def stop(self, grace_s: float = 5.0) -> None:
        for sig in (signal.SIGTERM, signal.SIGKILL):
            for pid in self._pids():
                try:
                    os.kill(pid, sig)
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + grace_s
            while self._pids() and time.monotonic() < deadline:
                time.sleep(0.2)
        shutil.rmtree(self.root, ignore_errors=True)


def _state(proc_dir: Path) -> str:
    return (proc_dir / "stat").read_text().rsplit(")", 1)[1].split()[0]


@pytest.fixture(scope="module")
def cluster():
    """Head and second node on this machine, token authentication on, as a user starts them: a token in ``HOME``
    (``ray get-auth-token --generate``), ``ray start --head`` (which turns token authentication on because the token
    exists), and ``ray start --address`` with ``RAY_AUTH_MODE=token`` on the second node, as Ray asks of every node
    joining such a cluster."""
    if RAY_CLI is None:
        pytest.skip(f"no `ray` command line (neither next to {sys.executable} nor on PATH)")
    # a short root: Ray's socket paths inside --temp-dir must stay under the 107-character limit of Unix sockets
    c = Cluster(Path(tempfile.mkdtemp(prefix="vbr-", dir="/tmp")))
    try:
        c.ray("get-auth-token", "--generate", timeout=60)
        head = c.start_node("--head", "--port", str(c.port), "--ray-client-server-port", str(_free_port()),
                            "--include-dashboard", "false")
        assert "Token authentication is enabled" in head, head[-2000:]
        c.token = (c.root / "home" / ".ray" / "auth_token").read_text().strip()
        c.start_node("--address", f"127.0.0.1:{c.port}", env={**c.env, RAY_AUTH_MODE_ENV: "token"})
        deadline = time.monotonic() + 60
        while c.alive_nodes(c.token) < 2 and time.monotonic() < deadline:
            time.sleep(0.5)
        yield c
    finally:
        c.stop()


@pytest.mark.slow
def test_an_audit_runs_across_a_cluster_started_with_ray_start_without_ray_auth_mode(cluster, tmp_path):
    assert cluster.alive_nodes(cluster.token) == 2
    assert ray_rejects("127.0.0.1", cluster.port, None, 10.0)  # token authentication is on
    out = tmp_path / "run"
    env = {**cluster.env, "VBL_ROBUST_WORKERS": "1"}  # no RAY_AUTH_MODE, no token variable: ~/.ray/auth_token
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", "from vbl_robust.cli import main; main()", *SMALL_AUDIT,
                           "--address", f"127.0.0.1:{cluster.port}", "--out", str(out)],
                          env=env, capture_output=True, text=True, timeout=300)
    seconds = time.monotonic() - start
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "InvalidAuthToken" not in proc.stdout + proc.stderr
    with ResultStore(out / "results.sqlite", readonly=True) as st:
        jobs = list(st.jobs(with_trace=False))
        runs = st.runs()
    assert len(jobs) == 2 and {str(j.status) for j in jobs} == {"done"}, jobs
    assert [(str(r.status), r.provenance.executor) for r in runs] == [("finished", "ray")]
    assert cluster.alive_nodes(cluster.token) == 2, f"a node left the cluster during the audit ({seconds:.0f} s)"


@pytest.mark.slow
@pytest.mark.parametrize("auto, setting, message", [
    (False, {}, "the cluster uses token authentication and no token was found"),
    (True, {}, "the cluster uses token authentication and no token was found"),  # Ray's lookup: RAY_ADDRESS
    (False, {RAY_AUTH_TOKEN_ENV: "not-the-head-token"}, "the cluster rejects the token from RAY_AUTH_TOKEN"),
    (False, {RAY_AUTH_MODE_ENV: "disabled"}, "the cluster uses token authentication but RAY_AUTH_MODE=disabled"),
])
def test_a_missing_or_wrong_token_is_refused_in_one_line_at_once(cluster, auth_env, tmp_path, auto, setting,
                                                               message):
    os.environ.update(setting)
    address = f"127.0.0.1:{cluster.port}"
    if auto:
        os.environ["RAY_ADDRESS"], address = address, "auto"
    start = time.monotonic()
    res = CliRunner().invoke(app, [*SMALL_AUDIT, "--address", address, "--out", str(tmp_path / "run")])
    assert time.monotonic() - start < 15
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: --address {address}: {message}"), res.output
    assert not (tmp_path / "run" / "results.sqlite").exists()
