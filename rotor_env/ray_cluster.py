"""Starting Ray for the batch diagnosis and the monitor's fleet (one place for both)."""

from __future__ import annotations

__all__ = ["init_ray"]


def init_ray(workers: int, address: str | None):
    """Ray's local mode with ``workers`` CPUs, or the cluster at ``address``.  Returns
    True when this call started Ray (and so should shut it down)."""
    import logging

    import ray

    if ray.is_initialized():
        return False
    kwargs = {"include_dashboard": False, "log_to_driver": False, "logging_level": logging.ERROR}
    if address:
        ray.init(address=address, **kwargs)
    else:
        ray.init(num_cpus=workers, **kwargs)
    return True
