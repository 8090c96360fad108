"""``cdr-bench evaluate --backend ray``: the evaluator's episode batches as Ray tasks.

A batch is the same pure function of (agent file, scenario, base seed, batch index) on either
backend (:func:`cdr_bench.evaluate.runner.run_batch_task`), and the evaluator orders batches
by index before writing, so the result files equal those of the local backend outside
``timing``. Every node must see the agent file at the same path (one machine, or a shared
file system).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

from cdr_bench.errors import UserError
from cdr_bench.evaluate.api import register_backend


def run_tasks_on_ray(
    tasks: list[tuple[Any, ...]], workers: int, address: str | None
) -> Iterator[dict[str, Any]]:
    """Yield the batch dicts of ``tasks`` as they finish; at most ``workers`` in flight when
    Ray is started here, every task at once on a cluster (Ray queues them)."""
    try:
        import ray
    except ImportError:
        raise UserError('--backend ray needs Ray: pip install "cdr-bench[ray]"') from None
    from cdr_bench.evaluate.runner import run_batch_task
    from cdr_bench.scale.sweep import ray_init

    os.environ.setdefault("RAY_ACCEL_ENV_VAR_OVERRIDE_ON_ZERO", "0")
    started = not ray.is_initialized()
    if started:
        ray_init(ray, address, None if address else workers)
    # an agent error is the agent's, not the worker's: do not retry it
    remote = ray.remote(run_batch_task).options(num_cpus=1, max_retries=3, retry_exceptions=False)
    try:
        pending = [remote.remote(*t) for t in tasks]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=1.0)
            if not ready:  # a timeout, so that Ctrl-C is seen between waits
                continue
            try:
                yield ray.get(ready[0])
            except ray.exceptions.RayTaskError as e:
                cause = e.cause if isinstance(e.cause, BaseException) else None
                if cause is not None:
                    raise cause from None
                raise
    finally:
        for ref in pending:
            ray.cancel(ref)
        if started:
            ray.shutdown()


register_backend("ray", run_tasks_on_ray)
