"""One writer per store: only the driver process writes (Ray workers send their rows back to it), and one driver at
a time — a campaign or a merge holds :class:`WriterLock` on its store for its whole run (an OS file lock, released
when the process ends, however it ends), so two runs never mix in one store."""

from __future__ import annotations

from pathlib import Path


class WriterLock:
    """The one-writer lock of a store: an exclusive ``flock`` on ``<store>.lock`` (which holds the writer's PID) and
    on the store file itself, held from :meth:`acquire` to :meth:`release` or the end of the process. A second
    writer gets a ``ValueError`` naming the PID that holds it, or waits for it with ``wait=True``. The lock on the
    store file keeps a second writer out even when ``<store>.lock`` is deleted during a run (a new lock file would
    be a new, free lock); ``flock`` does not interfere with SQLite's own (POSIX) locks, so readers are unaffected."""

    def __init__(self, store_path: str | Path):
        self.store = Path(store_path)
        self.path = Path(f"{store_path}.lock")
        self._fds: list[int] = []

    def acquire(self, wait: bool = False) -> WriterLock:
        import fcntl
        import os

        fds = []
        try:
            for target in (self.path, self.store):
                fd = os.open(target, os.O_RDWR | os.O_CREAT, 0o644)
                fds.append(fd)
                fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            try:
                holder = self.path.read_text().strip() or "another process"
            except OSError:
                holder = "another process"
            for fd in fds:
                os.close(fd)
            raise ValueError(f"{self.path.parent}: in use by PID {holder} (another run is writing this store); wait "
                             "for it to end or write to another --out") from None
        try:
            os.ftruncate(fds[0], 0)
            os.pwrite(fds[0], str(os.getpid()).encode(), 0)
        except OSError as exc:  # e.g. a full disk: named after the lock file
            for fd in fds:
                os.close(fd)
            raise OSError(exc.errno, exc.strerror, str(self.path)) from None
        self._fds = fds
        return self

    def release(self) -> None:
        import fcntl
        import os

        for fd in self._fds:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
        self._fds = []

    def __enter__(self) -> WriterLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()

