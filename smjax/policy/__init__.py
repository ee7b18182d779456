"""Saved policies: the trained hierarchy a run writes beside its results (``RUN/policy``),
loaded without a trainer to act, evaluate and render (``smjax.load_policy``)."""
from smjax.policy.artifact import PolicyError
from smjax.policy.load import load_policy
from smjax.policy.saved import PolicyParams, SavedPolicy

__all__ = ["load_policy", "SavedPolicy", "PolicyParams", "PolicyError"]
