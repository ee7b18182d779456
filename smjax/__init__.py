"""smjax: vectorized reinforcement learning with option templates, in JAX."""
from smjax.core.registry import make, registry

__version__ = "0.1.0"
__all__ = ["make", "registry", "__version__"]
