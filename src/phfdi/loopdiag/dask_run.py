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


def default_workers() -> int:
    return max(1, min(2, os.cpu_count() or 1))


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, processes: bool = True) -> Iterator:
    """A ``distributed.Client``: to ``scheduler`` when given, else to a new LocalCluster with
    ``workers`` single-threaded workers (processes unless ``processes`` is False), closed on exit."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout="10s")
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
