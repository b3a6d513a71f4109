"""Many independent loop jobs on Dask: a local cluster by default, an existing one by address.

Plant-wide work (thousands of loops, the classifier's training set) runs here rather than on a
home-made pool: ``dask.distributed`` gives a LocalCluster on this machine's cores by default and
connects to a running scheduler (``tcp://host:8786``) when given one, with the same code.
"""

from __future__ import annotations

import contextlib
import os
from typing import Callable, Iterable, Iterator

from phfdi_base.errors import UserError

#: how long reaching a running scheduler may take (s): the TCP connection and distributed's handshake together
CONNECT_TIMEOUT_S = 5.0
#: address schemes of a scheduler on another process or machine (distributed's ``inproc`` is in-process only)
REMOTE_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")


def check_scheduler_address(address: str) -> None:
    """One line (:class:`UserError`) unless ``address`` is one distributed can dial: SCHEME://HOST:PORT."""
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)  # no scheme: tcp
        host, port = parse_host_port(location)
    except ValueError as exc:
        raise UserError(f"Dask scheduler address {address!r}: {exc}; give tcp://HOST:PORT, e.g. "
                        f"tcp://10.0.0.5:8786") from None
    if scheme not in REMOTE_SCHEMES:
        hint = " (a scheduler listens on tcp://HOST:8786; http://HOST:8787 is its dashboard)" \
            if scheme in ("http", "https") else ""
        raise UserError(f"Dask scheduler address {address!r}: unknown scheme {scheme!r}, use one of "
                        f"{', '.join(REMOTE_SCHEMES)}{hint}")
    if not host or not 1 <= int(port) <= 65535:
        raise UserError(f"Dask scheduler address {address!r}: give a host and a port 1 .. 65535, e.g. "
                        f"tcp://10.0.0.5:8786")


def _reach(address: str, timeout_s: float) -> None:
    """Connect to the scheduler and complete distributed's handshake within ``timeout_s``, else one line. The
    Client's own timeout bounds the TCP connect but not the handshake's read: a listener that accepts and never
    answers held it for more than 100 s."""
    import asyncio

    from distributed.comm import connect

    async def handshake() -> None:
        # distributed's own limit (its retries of a refused connection, then its OSError naming the cause) a little
        # inside ours (a handshake that never comes)
        comm = await asyncio.wait_for(connect(address, timeout=0.8 * timeout_s), timeout_s)
        await comm.close()

    try:
        asyncio.run(handshake())
    except TimeoutError:
        raise UserError(f"the Dask scheduler at {address} did not answer within {timeout_s:g} s") from None
    except OSError as exc:
        raise UserError(f"cannot reach the Dask scheduler at {address}: {exc}") from None


def default_workers() -> int:
    return max(1, min(2, os.cpu_count() or 1))


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, processes: bool = True) -> Iterator:
    """A ``distributed.Client``: to ``scheduler`` when given, else to a new LocalCluster with
    ``workers`` single-threaded workers (processes unless ``processes`` is False), closed on exit."""
    from distributed import Client, LocalCluster

    if scheduler:
        check_scheduler_address(scheduler)
        _reach(scheduler, CONNECT_TIMEOUT_S)
        try:
            client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S:g}s")
        except (OSError, TimeoutError) as exc:
            raise UserError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
        try:
            yield client
        finally:
            client.close()
        return
    n = default_workers() if workers is None else max(1, workers)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=processes, dashboard_address=None,
                           silence_logs=40)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def chunk_size(n_items: int, client) -> int:
    """Items per task: enough tasks for every worker thread to get about 8 (load balance, and a
    progress line every few percent), at most 16 items per task. A loop takes a few tenths of a
    second, so one task per loop spends a few percent of the run on scheduling and messages."""
    try:
        threads = max(1, sum(client.nthreads().values()))
    except Exception:  # noqa: BLE001 - a client that cannot say: one item per task
        return 1
    return max(1, min(16, n_items // (8 * threads)))


def _apply_chunk(func: Callable, chunk: list) -> list:
    return [func(x) for x in chunk]


def map_ordered(client, func: Callable, items: Iterable, progress: Callable[[int, int], None] | None = None,
                chunk: int = 1) -> list:
    """``func`` over ``items`` on the cluster; results in the order of ``items``; ``progress(done,
    total)`` (items) after each finished task. ``chunk`` items go to the workers per task."""
    from distributed import as_completed

    items = list(items)
    chunk = max(1, int(chunk))
    pieces = [items[i:i + chunk] for i in range(0, len(items), chunk)]
    if chunk == 1:
        futures = client.map(func, items, pure=False)
    else:
        futures = client.map(_apply_chunk, [func] * len(pieces), pieces, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    out: list = [None] * len(pieces)
    done = 0
    for fut in as_completed(futures):
        k = index[fut.key]
        out[k] = fut.result() if chunk > 1 else [fut.result()]
        fut.release()
        done += len(pieces[k])
        if progress:
            progress(done, len(items))
    return [r for piece in out for r in piece]
