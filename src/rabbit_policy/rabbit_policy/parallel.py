"""Where the embarrassingly parallel jobs run: ES rollouts, PPO environments, evaluation
sweeps and gait-optimisation candidates all go through one :class:`Backend` (``map(fn,
items)``, results in the order of ``items``).

* ``local`` (the default): a ``multiprocessing`` fork pool of ``workers`` processes on this
  machine (none with one worker). Needs nothing running.
* ``ray``: Ray tasks. Without an address a private Ray instance is started on this machine
  (``workers`` CPUs, listening on 127.0.0.1, no dashboard, usage statistics off) and
  stopped by :meth:`Backend.close`; with an address (``auto`` or ``host:port``) it joins
  an existing cluster and leaves it running. A task whose worker or node dies is re-run
  by Ray (``max_retries``); its result is collected once, so nothing is lost or counted
  twice.

Job functions must be module-level (picklable) and pure functions of their item; state a
worker keeps between items (a compiled model, an environment) lives in module-level caches
keyed by what built it, so both backends run the same code with the same results.
"""

from __future__ import annotations

import os
import signal
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Any, Callable, Iterable

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

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> list:
        items = list(items)
        return self._pool.map(fn, items) if self._pool is not None else [fn(item) for item in items]

    def close(self, terminate: bool = False) -> None:
        if self._pool is None:
            return
        if terminate:
            self._pool.terminate()
        else:
            self._pool.close()
        self._pool.join()
        self._pool = None


class RayBackend:
    """Ray tasks, on a private local instance or an existing cluster (see the module docstring)."""

    kind = "ray"

    def __init__(self, workers: int, address: str | None = None, max_retries: int = 3) -> None:
        try:
            import ray
        except ImportError:
            raise BackendUnavailable("--backend ray needs the ray package (pip install ray==2.60.0)") from None
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no traffic to Anyscale
        self._ray = ray
        self.workers = workers
        self.max_retries = max_retries
        self.started = False
        if ray.is_initialized():
            pass  # already connected (a test's cluster, a caller's session): use it as it is
        elif address is None:
            try:
                ray.init(address="local", num_cpus=workers, include_dashboard=False, _node_ip_address="127.0.0.1",
                         log_to_driver=False, configure_logging=False)
            except Exception as exc:  # noqa: BLE001 - Ray raises many kinds at start-up
                raise BackendUnavailable(f"could not start a local Ray instance: {exc}") from None
            self.started = True
        else:
            try:
                ray.init(address=address, include_dashboard=False, log_to_driver=False, configure_logging=False)
            except Exception as exc:  # noqa: BLE001
                first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                raise BackendUnavailable(f"cannot join the Ray cluster at {address!r}: {first}") from None
        self._remote: dict[Callable, Any] = {}

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> list:
        remote = self._remote.get(fn)
        if remote is None:
            remote = self._remote[fn] = self._ray.remote(max_retries=self.max_retries, num_cpus=1)(fn)
        return self._ray.get([remote.remote(item) for item in items])

    def close(self, terminate: bool = False) -> None:
        """Stop the private instance this backend started (a joined cluster stays up)."""
        if self.started and self._ray.is_initialized():
            self._ray.shutdown()
        self.started = False


Backend = LocalBackend | RayBackend


def make_backend(config: BackendConfig) -> Backend:
    """The backend for ``config``; raises :class:`BackendUnavailable` with one line."""
    if config.kind == "ray":
        return RayBackend(config.workers, config.address)
    return LocalBackend(config.workers)


def add_backend_arguments(parser) -> None:
    """``--backend`` and ``--ray-address`` for a script's argument parser (``--workers`` is
    the script's own)."""
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="local: a process pool on this machine (default); ray: Ray tasks (a private local "
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
