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


def map_ordered(client, func: Callable, items: Iterable, progress: Callable[[int, int], None] | None = None) -> list:
    """``func`` over ``items`` on the cluster; results in the order of ``items``; ``progress(done,
    total)`` after each finished task."""
    from distributed import as_completed

    items = list(items)
    futures = client.map(func, items, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    out: list = [None] * len(items)
    for done, fut in enumerate(as_completed(futures), start=1):
        out[index[fut.key]] = fut.result()
        fut.release()
        if progress:
            progress(done, len(items))
    return out
