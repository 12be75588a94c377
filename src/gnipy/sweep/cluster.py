"""The dask.distributed cluster a sweep runs on: the caller's client, an existing scheduler
(its address checked before anything is contacted), or a local cluster without a dashboard."""

from __future__ import annotations

import json
import os
import re
from typing import Any

from ..extras import require
from .errors import SweepError, SweepFailure, why

__all__ = ["DEFAULT_CONNECT_TIMEOUT", "Cluster", "scheduler_address"]

#: Seconds to wait for the connection to an existing scheduler (`run_sweep(connect_timeout=...)`).
DEFAULT_CONNECT_TIMEOUT = 10.0

# HOST:PORT (a name, an IPv4 address, or an IPv6 address in brackets)
_HOST_PORT = re.compile(r"^(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9._-]*[A-Za-z0-9])?):(\d{1,5})$")
_NETWORK_PROTOCOLS = ("tcp", "tls", "ws", "wss", "ucx")


def default_workers() -> int:
    """The size of a local cluster: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def scheduler_address(scheduler, *, _from_file: str | None = None) -> str:
    """The address to connect to for `scheduler` (an address or a scheduler file), or a
    SweepError (`scheduler: ...`); nothing is contacted."""
    where = f" (in the scheduler file {_from_file!r})" if _from_file else ""
    usage = ("an address tcp://HOST:PORT, tls://HOST:PORT, inproc://..., HOST:PORT, or a "
             "scheduler file (JSON, from `dask scheduler --scheduler-file`)")
    if not isinstance(scheduler, str) or not scheduler.strip():
        raise SweepError(f"scheduler: expected {usage}, got {scheduler!r}{where}")
    text = scheduler.strip()
    if "://" in text:
        protocol, _, location = text.partition("://")
        if protocol == "inproc":
            if location and not any(c.isspace() for c in location):
                return text
        elif protocol in _NETWORK_PROTOCOLS:
            m = _HOST_PORT.match(location)
            if m and 0 < int(m.group(1)) < 65536:
                return text
        raise SweepError(f"scheduler: {text!r}{where} is not a valid address; expected {usage}")
    m = _HOST_PORT.match(text)
    if m and 0 < int(m.group(1)) < 65536:
        return "tcp://" + text
    if _from_file is None and os.path.isfile(os.path.expanduser(text)):
        try:
            with open(os.path.expanduser(text), encoding="utf-8") as fh:
                address = json.load(fh)["address"]
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise SweepError(
                f"scheduler: {text!r} is not a scheduler file (JSON with the scheduler's address): {why(e)}"
            ) from None
        return scheduler_address(address, _from_file=text)
    raise SweepError(
        f"scheduler: {text!r}{where} is neither a valid address nor a scheduler file that "
        f"exists; expected {usage}"
    )


def local_cluster_kwargs(workers: int) -> dict[str, Any]:
    """The arguments of the local `distributed.LocalCluster`: single-threaded worker
    processes, and no dashboard (the scheduler's HTTP server, which always starts, listens on
    a random port of 127.0.0.1 instead of 8787; its pages are switched off with the
    configuration `distributed.scheduler.http.routes = []` while it starts)."""
    import logging

    return dict(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address="127.0.0.1:0",
        scheduler_kwargs={"dashboard": False},
        worker_dashboard_address=None,
        silence_logs=logging.ERROR,
    )


class Cluster:
    """`with Cluster(...) as client`: the caller's client, one connected to `address` (within
    `connect_timeout` seconds), or a new local cluster of `workers` processes (closed on exit)."""

    def __init__(self, client, address, workers, connect_timeout, scheduler=None):
        self.given, self.address, self.workers = client, address, workers
        self.connect_timeout, self.scheduler = connect_timeout, scheduler
        self.client = self.cluster = None

    def __enter__(self):
        require("distributed", extra="sweeps")
        import dask
        from distributed import Client, LocalCluster

        if self.given is not None:
            self.client = self.given
            return self.client
        if self.address is not None:
            try:
                self.client = Client(self.address, timeout=self.connect_timeout, set_as_default=False)
            except Exception as e:  # noqa: BLE001 - refused, timed out, bad TLS, ...
                raise SweepError(
                    f"scheduler: cannot connect to {self.scheduler!r} within {self.connect_timeout:g} s "
                    f"({why(e)}); check the address and that the scheduler runs, or raise connect_timeout"
                ) from None
            return self.client
        try:
            with dask.config.set({"distributed.scheduler.http.routes": []}):
                self.cluster = LocalCluster(**local_cluster_kwargs(self.workers))
            self.client = Client(self.cluster, set_as_default=False)
        except Exception as e:  # noqa: BLE001
            self.__exit__()
            raise SweepFailure(f"cannot start a local cluster: {type(e).__name__}: {e}") from e
        return self.client

    def __exit__(self, *exc):
        if self.client is not None and self.client is not self.given:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        return False
