"""Training: top-down (the paper's method), bottom-up option-value iteration, flat."""
from smjax.train.config import ALGOS, METHODS, ConfigError, TrainConfig
from smjax.train.hooks import ChunkReport, Hook, ResultsReport
from smjax.train.run import run

__all__ = ["TrainConfig", "ConfigError", "METHODS", "ALGOS", "run", "Hook", "ChunkReport",
           "ResultsReport"]
