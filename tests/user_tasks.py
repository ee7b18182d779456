"""A user's own task module, as the CLI imports it (``--import user_tasks`` or the task
name ``user_tasks:userkd/open_door``): it registers a task when imported."""
from hier_env import make_keydoor
from smjax.core import register
from smjax.core.overrides import parse_int


def _factory(*, max_steps: int = 20):
    # a task checks its overrides as smjax's own do (tests/test_hostile_inputs.py tries
    # every registered task, this one included once a test has imported it)
    env, params = make_keydoor()
    return env, params.replace(max_steps=parse_int("max_steps", max_steps, 1, 2**31 - 1))


register("userkd/open_door", _factory, "the test key-door world, registered by a user module")
