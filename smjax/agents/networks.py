"""Networks shared by the learners, and the masked action distributions built on them.

Every network takes a *flat* float32 batch ``[N, F]``; :func:`flatten_obs` turns any
observation batch (uint8 grids, bool masks, float vectors) into that form. Keeping the
input flat means ``policy_logits(params, obs)`` needs nothing but the params, which is
what lets the trainer stack several learned policies into one "policy bank" pytree.

Masking: a masked action gets the logit :data:`MASKED_LOGIT`, a large *finite* negative
number. Its softmax probability is exactly 0 in float32, and unlike ``-inf`` it keeps
entropies and log-probabilities finite even when a whole row is masked (ticks where the
learner does not decide may carry an all-False mask).
"""
from __future__ import annotations

from typing import Callable, Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from smjax.core.layout import Grid, check_layout, flat_rest

MASKED_LOGIT = -1e9

ACTIVATIONS: dict[str, Callable[[jax.Array], jax.Array]] = {
    "tanh": jnp.tanh,
    "relu": nn.relu,
    "gelu": nn.gelu,
    "elu": nn.elu,
    "swish": nn.swish,
}


def activation_by_name(name: str) -> Callable[[jax.Array], jax.Array]:
    if name not in ACTIVATIONS:
        raise ValueError(f"unknown activation {name!r}; valid: {', '.join(sorted(ACTIVATIONS))}")
    return ACTIVATIONS[name]


def flatten_obs(obs: jax.Array, batch_dims: int = 1) -> jax.Array:
    """Cast to float32 and merge every non-batch axis: ``[*batch, ...] -> [*batch, F]``."""
    obs = jnp.asarray(obs)
    lead = obs.shape[:batch_dims]
    return obs.reshape(lead + (-1,)).astype(jnp.float32)


def _dense(features: int, scale: float, name: str | None = None) -> nn.Dense:
    # Orthogonal init with per-layer gains (sqrt(2) hidden, 0.01 policy, 1.0 value) is the
    # standard PPO recipe: small initial logits give a near-uniform starting policy.
    return nn.Dense(
        features,
        kernel_init=nn.initializers.orthogonal(scale),
        bias_init=nn.initializers.constant(0.0),
        name=name,
    )


class MLP(nn.Module):
    """Stack of dense layers with an activation after each."""

    hidden_sizes: Sequence[int]
    activation: str = "tanh"

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        act = activation_by_name(self.activation)
        for size in self.hidden_sizes:
            x = act(_dense(size, float(np.sqrt(2)))(x))
        return x


def _patches_3x3(cells: jax.Array) -> jax.Array:
    """``[..., H, W, C] -> [..., H, W, 9C]``: each cell's 3 x 3 neighbourhood (zeros past
    the border), so that a dense layer on it is a 3 x 3 convolution with same padding.
    Why not ``nn.Conv``: on XLA:CPU a PPO update with two 5 x 5 convolutions takes about
    87 times the dense one; as nine shifted views and one matrix product it is a plain
    GEMM."""
    height, width = cells.shape[-3], cells.shape[-2]
    padded = jnp.pad(cells, [(0, 0)] * (cells.ndim - 3) + [(1, 1), (1, 1), (0, 0)])
    views = [padded[..., i:i + height, j:j + width, :] for i in range(3) for j in range(3)]
    return jnp.concatenate(views, axis=-1)


class GridEncoder(nn.Module):
    """Flat observations ``[N, F]`` -> features ``[N, F']``: every declared grid
    (``smjax.core.layout.Grid``: ``(start, height, width, channels)``) is reshaped and
    read by its own stack of 3 x 3 convolutions (``features`` channels per layer, the
    same height and width), then flattened beside the values no grid covers.

    Why: a dense first layer must learn what a kind of cell means at every cell of a
    window separately; a convolution learns it once for every position (Craft's paper
    observation: two 5 x 5 windows of 31 kinds)."""

    grids: Sequence[tuple[int, int, int, int]]
    features: Sequence[int] = (16, 16)
    activation: str = "relu"

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        act = activation_by_name(self.activation)
        grids = check_layout(self.grids, x.shape[-1])
        lead = x.shape[:-1]
        parts = []
        for g, grid in enumerate(grids):
            cells = x[..., grid.start:grid.stop]
            cells = cells.reshape(lead + (grid.height, grid.width, grid.channels))
            for layer, size in enumerate(self.features):
                conv = _dense(size, float(np.sqrt(2)), name=f"grid_{g}_conv_{layer}")
                cells = act(conv(_patches_3x3(cells)))
            parts.append(cells.reshape(lead + (-1,)))
        rest = np.asarray(flat_rest(grids, x.shape[-1]), np.int32)
        return jnp.concatenate(parts + [x[..., rest]], axis=-1)


def torso_grids(torso: str, layout) -> tuple:
    """The grids a network's ``GridEncoder`` reads: the observation's declared ``layout``
    (``Environment.observation_layout``) for a "conv" torso, none for "mlp". Asked when a
    network is built (``init``), so an agent made only to read its settings (a sweep's
    check) needs no layout."""
    if torso != "conv":
        return ()
    if not layout:
        raise ValueError("torso 'conv' needs an observation that declares grids "
                         "(Environment.observation_layout); this one declares none: use "
                         "torso 'mlp'")
    return tuple(Grid(*g) for g in layout)


def encoded(x: jax.Array, grids, features, activation: str = "relu") -> jax.Array:
    """``x`` through a ``GridEncoder`` (named ``grid_encoder``) where ``grids`` are
    declared, else unchanged (a network without grids keeps the same parameters)."""
    if not grids:
        return x
    return GridEncoder(tuple(grids), tuple(features), activation, name="grid_encoder")(x)


class ActorCritic(nn.Module):
    """Actor logits ``[N, A]`` and state values ``[N]`` from flat observations ``[N, F]``.

    ``shared_torso=True`` feeds both heads from one MLP; otherwise actor and critic have
    their own MLP of the same shape (PPO's usual choice, and the paper's learner).
    """

    num_actions: int
    hidden_sizes: Sequence[int] = (64, 64)
    activation: str = "tanh"
    shared_torso: bool = False
    grids: Sequence[tuple[int, int, int, int]] = ()   # GridEncoder's, shared by both heads
    conv_features: Sequence[int] = (16, 16)

    @nn.compact
    def __call__(self, x: jax.Array) -> tuple[jax.Array, jax.Array]:
        x = encoded(x, self.grids, self.conv_features)
        if self.shared_torso:
            features = MLP(self.hidden_sizes, self.activation, name="torso")(x)
            actor_features = critic_features = features
        else:
            actor_features = MLP(self.hidden_sizes, self.activation, name="actor_torso")(x)
            critic_features = MLP(self.hidden_sizes, self.activation, name="critic_torso")(x)
        logits = _dense(self.num_actions, 0.01, name="policy_head")(actor_features)
        value = _dense(1, 1.0, name="value_head")(critic_features)
        return logits, value[..., 0]


class RecurrentActorCritic(nn.Module):
    """``ActorCritic`` with a memory: a GRU cell of width ``memory_size`` carried from one
    of the policy's decisions to the next. ``(x [N, F], h [N, H]) -> (logits [N, A],
    values [N], h' [N, H])``; the actor's features drive the cell, and both heads read
    their own features beside ``h'``, so a zero memory still gives a feed-forward policy's
    inputs. ``encode`` (the torsos, which do not read the memory) and ``decide`` (the cell
    and heads) are apart so that a replay over a rollout runs the wide first layers once
    for every tick and only the small cell step by step."""

    num_actions: int
    hidden_sizes: Sequence[int] = (64, 64)
    activation: str = "tanh"
    memory_size: int = 64

    def setup(self):
        self.actor_torso = MLP(self.hidden_sizes, self.activation)
        self.critic_torso = MLP(self.hidden_sizes, self.activation)
        self.memory = nn.GRUCell(self.memory_size)
        self.policy_head = _dense(self.num_actions, 0.01)
        self.value_head = _dense(1, 1.0)

    def __call__(self, x: jax.Array, h: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        return self.decide(self.encode(x), h)

    def encode(self, x: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(actor features, critic features) of flat observations (any leading axes)."""
        return self.actor_torso(x), self.critic_torso(x)

    def decide(self, features, h: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
        actor, critic = features
        h, _ = self.memory(h, actor)
        logits = self.policy_head(jnp.concatenate([actor, h], -1))
        value = self.value_head(jnp.concatenate([critic, h], -1))
        return logits, value[..., 0], h


class QNetwork(nn.Module):
    """Action values ``[N, A]`` from flat observations ``[N, F]``."""

    num_actions: int
    hidden_sizes: Sequence[int] = (64, 64)
    activation: str = "relu"
    grids: Sequence[tuple[int, int, int, int]] = ()
    conv_features: Sequence[int] = (16, 16)

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        x = encoded(x, self.grids, self.conv_features)
        features = MLP(self.hidden_sizes, self.activation, name="torso")(x)
        return _dense(self.num_actions, 1.0, name="q_head")(features)


# ---- masked action distributions --------------------------------------------------

def masked_logits(logits: jax.Array, mask: jax.Array) -> jax.Array:
    return jnp.where(mask, logits, MASKED_LOGIT)


def masked_log_softmax(logits: jax.Array, mask: jax.Array) -> jax.Array:
    return jax.nn.log_softmax(masked_logits(logits, mask), axis=-1)


def masked_entropy(logits: jax.Array, mask: jax.Array) -> jax.Array:
    """Entropy of the masked softmax; masked actions contribute exactly 0."""
    log_p = masked_log_softmax(logits, mask)
    p = jnp.exp(log_p)
    return -jnp.sum(jnp.where(mask, p * log_p, 0.0), axis=-1)


def uniform_allowed_probs(mask: jax.Array) -> jax.Array:
    """Uniform distribution over the allowed actions (all actions if none is allowed)."""
    mask_f = mask.astype(jnp.float32)
    count = mask_f.sum(-1, keepdims=True)
    # An all-False row (a tick where the learner has no choice) falls back to uniform
    # over everything so probabilities stay well defined; the caller ignores that action.
    return jnp.where(count > 0, mask_f / jnp.maximum(count, 1.0), 1.0 / mask.shape[-1])


def epsilon_mixture_log_probs(
    base_log_probs: jax.Array, mask: jax.Array, epsilon: jax.Array
) -> jax.Array:
    """Log-probabilities of "with prob. epsilon uniform over allowed, else base"."""
    mixed = (1.0 - epsilon) * jnp.exp(base_log_probs) + epsilon * uniform_allowed_probs(mask)
    return jnp.log(jnp.maximum(mixed, 1e-30))


def sample_from_log_probs(key: jax.Array, log_probs: jax.Array, mask: jax.Array) -> jax.Array:
    """Sample ``[N]`` int32 actions; masked actions are excluded even if rounding leaks mass."""
    return jax.random.categorical(key, masked_logits(log_probs, mask), axis=-1).astype(jnp.int32)


def greedy_masked(scores: jax.Array, mask: jax.Array) -> jax.Array:
    return jnp.argmax(masked_logits(scores, mask), axis=-1).astype(jnp.int32)


def epsilon_greedy_log_probs(scores: jax.Array, mask: jax.Array, epsilon: jax.Array) -> jax.Array:
    """Log-probabilities of epsilon-greedy over allowed actions (greedy = masked argmax)."""
    greedy = jax.nn.one_hot(greedy_masked(scores, mask), scores.shape[-1])
    probs = (1.0 - epsilon) * greedy + epsilon * uniform_allowed_probs(mask)
    return jnp.log(jnp.maximum(probs, 1e-30))


def masked_mean(values: jax.Array, weights: jax.Array) -> jax.Array:
    """Mean of ``values`` over entries with weight 1 (0 if there are none, never NaN)."""
    weights = weights.astype(jnp.float32)
    # where, not a product: a NaN on a weight-0 entry (e.g. an unused field of a
    # non-decision tick) must not poison the mean.
    total = jnp.sum(jnp.where(weights > 0, values * weights, 0.0))
    return total / jnp.maximum(jnp.sum(weights), 1.0)


def take_action(per_action: jax.Array, action: jax.Array) -> jax.Array:
    """``per_action[..., action]`` for a batch of int actions (indices clipped into range,
    since ticks where the learner did not decide may carry any action value)."""
    index = jnp.clip(action.astype(jnp.int32), 0, per_action.shape[-1] - 1)
    return jnp.take_along_axis(per_action, index[..., None], axis=-1)[..., 0]
