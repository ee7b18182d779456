"""A user's own task module, as the CLI imports it (``--import user_tasks`` or the task
name ``user_tasks:userkd/open_door``): it registers a task when imported."""
from hier_env import make_keydoor
from smjax.core import register


def _factory(*, max_steps: int = 20):
    env, params = make_keydoor()
    return env, params.replace(max_steps=max_steps)


register("userkd/open_door", _factory, "the test key-door world, registered by a user module")
