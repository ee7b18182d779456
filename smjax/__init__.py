"""smjax: vectorized reinforcement learning with option templates, in JAX."""
import os as _os

# XLA:CPU (jaxlib 0.10) can deadlock executing larger vmapped programs (every thread
# waiting, no progress; seen with batched network inits and 64-env MJX batches) under its
# concurrency-optimized scheduler. Turning that scheduler off avoids it. The flag must be
# set before the first computation; SMJAX_XLA_WORKAROUND=0 leaves XLA_FLAGS alone.
_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler=false"
if _os.environ.get("SMJAX_XLA_WORKAROUND", "1") != "0" and \
        "xla_cpu_enable_concurrency_optimized_scheduler" not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + " " + _FLAG).strip()

from smjax.core.registry import make, registry  # noqa: E402
from smjax.core.version import smjax_version  # noqa: E402

__version__ = smjax_version()  # the installed distribution's; "0+unknown" in a bare source tree
__all__ = ["make", "registry", "load_policy", "__version__"]


def __getattr__(name: str):
    """``smjax.load_policy``, imported when first used: importing any part of smjax
    (``smjax.core`` for an environment alone) does not load the learners."""
    if name == "load_policy":
        from smjax.policy import load_policy

        return load_policy
    raise AttributeError(f"module 'smjax' has no attribute {name!r}")
