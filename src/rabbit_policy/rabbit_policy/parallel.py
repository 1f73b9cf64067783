"""Where the embarrassingly parallel jobs run: ES rollouts, PPO environments, evaluation
sweeps and gait-optimisation candidates all go through one :class:`Backend` (``map(fn,
items)``, results in the order of ``items``).

* ``local`` (the default): a ``multiprocessing`` fork pool of ``workers`` processes on this
  machine (none with one worker). Needs nothing running.
* ``ray``: Ray tasks (and, for PPO, Ray actors: :mod:`rabbit_policy.learning.vector`).
  Without an address a private Ray instance is started on this machine (``workers`` CPUs,
  bound to and advertising 127.0.0.1 only, no dashboard, usage statistics off) and stopped
  by :meth:`Backend.close`; with an address (``auto`` or ``host:port``) it joins an
  existing cluster (checked with a TCP connection first: an unreachable address is a
  one-line error at once, where Ray itself retries for minutes) and only disconnects. A
  task whose worker process or node dies is re-run by Ray (``max_retries``); its result is
  collected once, so nothing is lost or counted twice. docs/cluster.md: a multi-machine
  cluster, step by step, and what it exposes.

Job functions must be module-level (picklable) and pure functions of their item; state a
worker keeps between items (a compiled model, an environment) lives in module-level caches
keyed by what built it, so both backends run the same code with the same results.
"""

from __future__ import annotations

import os
import signal
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable, Iterable

from rabbit_msgs_py.cli import positive_int

BACKENDS = ("local", "ray")


class BackendUnavailable(RuntimeError):
    """The requested backend cannot start (Ray missing, address unreachable, ...)."""


def ignore_interrupts() -> None:
    """For worker processes: Ctrl-C (SIGINT to the whole process group) is the parent's to
    handle; it then stops the workers itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@dataclass(frozen=True)
class BackendConfig:
    """``kind``: ``local`` or ``ray``; ``workers``: processes (local) or CPUs of a private
    Ray instance; ``address``: Ray only, None = start a private instance on this machine,
    ``auto`` or ``host:port`` = join that cluster."""

    kind: str = "local"
    workers: int = 2
    address: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.kind!r}")
        if not (isinstance(self.workers, int) and self.workers >= 1):
            raise ValueError(f"workers must be a whole number >= 1, got {self.workers!r}")
        if self.address is not None and self.kind != "ray":
            raise ValueError("a Ray address needs --backend ray")


class LocalBackend:
    """A fork pool of ``workers`` processes (the caller's process alone for one)."""

    kind = "local"

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._pool = get_context("fork").Pool(workers, initializer=ignore_interrupts) if workers > 1 else None

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any], on_each: Callable[[], None] | None = None) -> list:
        """``fn`` on every item, results in order; ``on_each()`` after each item is done."""
        results = []
        for result in (self._pool.imap(fn, items) if self._pool is not None else map(fn, items)):
            results.append(result)
            if on_each is not None:
                on_each()
        return results

    def close(self, terminate: bool = False) -> None:
        if self._pool is None:
            return
        if terminate:
            self._pool.terminate()
        else:
            self._pool.close()
        self._pool.join()
        self._pool = None


RAY_PIN = "ray==2.60.0"
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
CONNECT_TIMEOUT_S = 5.0


def split_address(address: str) -> tuple[str, int]:
    """``host:port`` -> (host, port); raises ``ValueError`` with one line."""
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"a Ray address is auto or host:port, got {address!r}")
    return host.strip("[]"), int(port)


def resolve_address(address: str) -> str:
    """The ``host:port`` of the cluster ``address`` names: itself, or for ``auto`` what Ray's
    own lookup finds, without importing Ray: the ``RAY_ADDRESS`` environment variable, else
    the cluster ``ray start --head`` last started on this machine (``ray_current_cluster`` in
    Ray's temporary directory). Raises :class:`BackendUnavailable` with one line."""
    if address == "auto":
        found = os.environ.get("RAY_ADDRESS", "")
        current = Path(os.environ.get("RAY_TMPDIR", "/tmp/ray")) / "ray_current_cluster"
        if not found and current.is_file():
            found = current.read_text().strip()
        if not found:
            raise BackendUnavailable("--ray-address auto: no running Ray cluster found on this machine "
                                     "(start one with `ray start --head`, or give host:port)")
        address = found
    try:
        split_address(address)
    except ValueError as exc:
        raise BackendUnavailable(str(exc)) from None
    return address


def probe(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Fail fast: a TCP connection to the cluster's GCS port (Ray itself retries for
    minutes before giving up on an unreachable address)."""
    import socket

    host, port = split_address(address)
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except OSError as exc:
        raise BackendUnavailable(f"cannot reach the Ray cluster at {address}: {exc.strerror or exc}") from None


class RayBackend:
    """Ray tasks, on a private local instance or an existing cluster (see the module docstring)."""

    kind = "ray"

    def __init__(self, workers: int, address: str | None = None, max_retries: int = 3) -> None:
        # decided before Ray is imported (it reads these once): no usage statistics sent, and a
        # private instance (or a cluster on this machine's loopback) binds and advertises
        # 127.0.0.1 only instead of the machine's network address
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
        if address is None:
            # a private instance authenticates its clients (Ray's default, said explicitly so
            # that Ray does not warn about it on every start)
            os.environ.setdefault("RAY_AUTH_MODE", "token")
        self.address = None if address is None else resolve_address(address)
        if self.address is not None:
            probe(self.address)
        if self.address is None or split_address(self.address)[0] in LOOPBACK_HOSTS:
            os.environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"
        try:
            import ray
        except ImportError:
            raise BackendUnavailable(f"--backend ray needs the ray package (pip install {RAY_PIN})") from None
        self._ray = ray
        self.workers = workers
        self.max_retries = max_retries
        self.owns_connection = False  # this backend connected (and disconnects, or stops its instance, on close)
        if ray.is_initialized():
            pass  # already connected (a test's cluster, a caller's session): used as it is, left open
        elif address is None:
            try:
                ray.init(address="local", num_cpus=workers, include_dashboard=False,
                         _node_ip_address="127.0.0.1", log_to_driver=False, configure_logging=False)
            except Exception as exc:  # noqa: BLE001 - Ray raises many kinds at start-up
                raise BackendUnavailable(f"could not start a local Ray instance: {_first_line(exc)}") from None
            self.owns_connection = True
            self._require_loopback()
        else:
            try:
                ray.init(address=self.address, log_to_driver=False, configure_logging=False)
            except Exception as exc:  # noqa: BLE001
                raise BackendUnavailable(f"cannot join the Ray cluster at {self.address}: {_join_error(exc)}") from None
            self.owns_connection = True
        self._remote: dict[Callable, Any] = {}

    def _require_loopback(self) -> None:
        """A private instance must be on 127.0.0.1 (Ray imported earlier in this process,
        before the loopback setting, would have picked the machine's address)."""
        addresses = {node["NodeManagerAddress"] for node in self._ray.nodes()}
        if addresses - {"127.0.0.1"}:
            self._ray.shutdown()
            raise BackendUnavailable(
                f"the private Ray instance would listen on {sorted(addresses)}, not 127.0.0.1: set "
                "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 before Ray is imported")

    @property
    def cpus(self) -> int:
        """CPUs the cluster offers to tasks (all nodes)."""
        return int(self._ray.cluster_resources().get("CPU", 0))

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any], on_each: Callable[[], None] | None = None) -> list:
        """``fn`` on every item as Ray tasks; results in order (``on_each()`` as each is done).
        A task whose worker process or node dies is re-run (up to ``max_retries``); an
        exception raised by ``fn`` itself is not retried and is raised here at once."""
        remote = self._remote.get(fn)
        if remote is None:
            remote = self._remote[fn] = self._ray.remote(max_retries=self.max_retries, num_cpus=1)(fn)
        refs = [remote.remote(item) for item in items]
        try:
            pending = refs
            while pending:
                done, pending = self._ray.wait(pending, num_returns=1)
                self._ray.get(done)  # a failed task raises now, not after the others
                if on_each is not None:
                    on_each()
            return self._ray.get(refs)
        except Exception:
            # a failed task: the others stop too, nothing keeps running on our behalf. Not on
            # Ctrl-C: the workers got the signal as well, and cancelling a task whose worker is
            # dying at that moment aborts the driver (Ray 2.60: "Tried to complete task that
            # was not pending"); close() ends them with the instance or the job
            _ready, pending = self._ray.wait(refs, num_returns=len(refs), timeout=0)
            for ref in pending:
                self._ray.cancel(ref, force=True)
            raise

    def actor(self, cls: type, *args: Any, num_cpus: float = 1.0):
        """A Ray actor ``cls(*args)`` holding ``num_cpus``, placed to spread over the nodes
        (not restarted when it dies: its state, an episode in progress, would be lost)."""
        return self._ray.remote(num_cpus=num_cpus, max_restarts=0, scheduling_strategy="SPREAD")(cls).remote(*args)

    def get(self, refs: list) -> list:
        """The results of actor calls, in order."""
        return self._ray.get(refs)

    def kill(self, actor) -> None:
        self._ray.kill(actor)

    @property
    def actor_errors(self) -> tuple[type[BaseException], ...]:
        """What :meth:`get` raises when an actor or its node died."""
        from ray.exceptions import ActorDiedError, ActorUnavailableError, RayActorError

        return (RayActorError, ActorDiedError, ActorUnavailableError)

    def close(self, terminate: bool = False) -> None:
        """Disconnect; a private instance this backend started is stopped with it (a joined
        cluster stays up, and ends the tasks of this driver)."""
        if self.owns_connection and self._ray.is_initialized():
            self._ray.shutdown()
        self.owns_connection = False


def _join_error(exc: BaseException) -> str:
    """Why joining failed, in one line: the root cause Ray chains under its ConnectionError."""
    cause = exc
    while cause.__cause__ is not None:
        cause = cause.__cause__
    if "AuthenticationError" in type(cause).__name__ or "InvalidAuthToken" in str(cause):
        return ("the cluster requires token authentication: set RAY_AUTH_MODE=token and its token "
                "(~/.ray/auth_token or RAY_AUTH_TOKEN), see docs/cluster.md")
    return _first_line(cause)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


Backend = LocalBackend | RayBackend


def make_backend(config: BackendConfig) -> Backend:
    """The backend for ``config``; raises :class:`BackendUnavailable` with one line."""
    if config.kind == "ray":
        return RayBackend(config.workers, config.address)
    return LocalBackend(config.workers)


class ProgressMap:
    """A backend's ``map`` with one progress bar (tqdm, on stderr) over all the walks it runs:
    the total grows as each sweep hands over its walks, the count as each walk ends. Pass it
    where a ``map_fn`` goes; :meth:`close` ends the bar."""

    def __init__(self, backend: "Backend", label: str = "walks", enabled: bool = True) -> None:
        from tqdm import tqdm

        self.backend = backend
        self.total = self.done = 0  # walks handed over, walks ended
        self.bar = tqdm(total=0, unit="walk", desc=label, disable=not enabled, dynamic_ncols=True)

    def __call__(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> list:
        items = list(items)
        self.total += len(items)
        self.bar.total = self.total
        self.bar.refresh()
        return self.backend.map(fn, items, on_each=self._one_done)

    def _one_done(self) -> None:
        self.done += 1
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


def add_backend_arguments(parser, progress: bool = False, workers: bool = True) -> None:
    """``--workers``, ``--backend`` and ``--ray-address`` for a script's argument parser (with
    ``workers`` False the script declares ``--workers`` itself: train.py's is a
    ``TrainingConfig`` field); with ``progress`` also ``--no-progress`` (for :class:`ProgressMap`)."""
    if workers:
        parser.add_argument("--workers", type=positive_int, default=2,
                            help="processes (local) or Ray CPUs for the independent walks (default 2)")
    if progress:
        parser.add_argument("--no-progress", action="store_true", help="no progress bar (log lines only)")
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="local: a process pool on this machine; ray: Ray tasks (a private local "
                             "instance, or the cluster at --ray-address)")
    parser.add_argument("--ray-address", default=None, metavar="ADDRESS",
                        help="--backend ray: join this cluster (auto, or host:port of `ray start --head`) "
                             "instead of starting a private instance")


def open_backend(parser, args) -> Backend:
    """The backend a script's parsed arguments ask for; a bad combination or a backend that
    cannot start ends the script with one line and exit status 2 (``parser.error``/``exit``)."""
    try:
        return make_backend(backend_config(args))
    except ValueError as exc:
        parser.error(str(exc))
    except BackendUnavailable as exc:
        parser.exit(2, f"error: {exc}\n")


def backend_config(args) -> BackendConfig:
    """The :class:`BackendConfig` of parsed ``--backend``/``--ray-address``/``--workers``
    (raises ``ValueError`` with one line)."""
    return BackendConfig(args.backend, args.workers, args.ray_address)
