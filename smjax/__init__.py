"""smjax: vectorized reinforcement learning with option templates, in JAX."""
import os as _os

# Two XLA:CPU settings, added to XLA_FLAGS before the first computation unless the user set
# them; SMJAX_XLA_WORKAROUND=0 leaves XLA_FLAGS alone.
# * XLA:CPU (jaxlib 0.10) can deadlock executing larger vmapped programs (every thread
#   waiting, no progress; seen with batched network inits and 64-env MJX batches) under its
#   concurrency-optimized scheduler. Turning that scheduler off avoids it.
# * XLA:CPU (jaxlib 0.10 and 0.11) hands dot products to YNNPACK. For these networks' small
#   layers (64 units, minibatches of a few hundred rows) its own Eigen dots are faster: a PPO
#   or football chunk 1.2-1.3x with 64 environments a seed, as fast or a little faster with
#   128 (benchmarks/RESULTS.md, "XLA:CPU's own dots"). Older jaxlibs do not know the flag (an
#   unknown flag stops XLA), so it goes only to these.


def _jaxlib_at_least(major: int, minor: int) -> bool:
    """From the installed metadata: importing jaxlib, or smjax.core (``smjax_version``'s
    module, whose imports might compute), could start XLA before its flags are set."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        installed = tuple(int(part) for part in version("jaxlib").split(".")[:2])
    except (PackageNotFoundError, ValueError):
        return False
    return installed >= (major, minor)


if _os.environ.get("SMJAX_XLA_WORKAROUND", "1") != "0":
    _flags = {"xla_cpu_enable_concurrency_optimized_scheduler": "false"}
    if _jaxlib_at_least(0, 10):
        _flags["xla_cpu_experimental_ynn_fusion_type"] = ""
    _given = _os.environ.get("XLA_FLAGS", "")
    _add = [f"--{name}={value}" for name, value in _flags.items() if name not in _given]
    if _add:
        _os.environ["XLA_FLAGS"] = " ".join([_given] + _add).strip()

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
