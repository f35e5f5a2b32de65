"""Where runs execute: this process (``--jobs 1``), local spawned processes (``--jobs N``) or a
dask.distributed cluster (``--executor dask --scheduler ADDRESS``).  All yield (spec, :class:`~gevi_cli.batch.worker.Finished`) as runs
finish; the results tree is the same whichever is used (each run writes only its own folder).
"""
from __future__ import annotations

from gevi_cli.batch.worker import run_one
from gevi_cli.errors import GeviError


def run_serial(specs):
    """In this process, one after the other (what tests monkeypatch)."""
    for spec in specs:
        yield spec, run_one(spec)


def run_local(specs, jobs: int):
    """``jobs`` spawned worker processes: spawn, not fork, so that no BLAS/OpenCV thread pool or lock
    of the parent is inherited (each run pins its own threads: :func:`gevi_cli.run.threads.one_thread`)."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    if jobs <= 1:
        yield from run_serial(specs)
        return
    with ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn")) as pool:
        futures = {pool.submit(run_one, s): s for s in specs}
        try:
            for fut in as_completed(futures):
                yield futures[fut], fut.result()
        except BaseException:
            for f in futures:
                f.cancel()
            raise


def run_dask(specs, scheduler: str):
    """On the dask.distributed cluster at ``scheduler`` (workers need gevi importable; each task pins
    its threads in :func:`gevi_cli.run.session.execute`).  ``pure=False``: a re-run of the same spec must run again."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise GeviError("--executor dask", "needs dask.distributed: pip install 'gevi[cluster]'") from None
    try:
        client = Client(scheduler, timeout="20s")
    except (OSError, TimeoutError) as exc:
        raise GeviError("--scheduler", f"cannot reach the dask scheduler at {scheduler}: {exc}") from None
    try:
        futures = {client.submit(run_one, s, pure=False, key=f"gevi-run-{s.run_id}"): s for s in specs}
        try:
            for fut in as_completed(futures):
                yield futures[fut], fut.result()
        except BaseException:
            client.cancel(list(futures))
            raise
    finally:
        client.close()


def execute_all(specs, executor: str, jobs: int, scheduler: str | None):
    if executor == "dask":
        if not scheduler:
            raise GeviError("--executor dask", "needs --scheduler ADDRESS (e.g. tcp://host:8786)")
        return run_dask(specs, scheduler)
    return run_local(specs, jobs)
