"""Hierarchies as data: indices, masks and clear errors naming the culprit."""
import pytest

from hier_env import KeyDoor
from smjax.options import Hierarchy, HierarchyError, OptionTemplate, declare


def _sat(s, p):
    return s.has_key


def test_paper_hierarchy_indices_and_levels():
    h = KeyDoor().hierarchies()["paper"]
    assert h.option_names == ("open_door", "give_key")
    assert h.learnable == ("open_door", "give_key")
    assert h.level("open_door") == 1 and h.level("give_key") == 2
    assert h.num_primitives == 3 and h.num_actions == 4
    assert h.action_index("give_key") == 3 and h.action_index("use") == 2
    mask = h.child_mask()
    assert mask.tolist() == [[True, True, True, True], [True, True, True, False]]
    assert h.stack_depth == 2


def test_leaf_templates_are_not_learnable():
    h = KeyDoor().hierarchies()["scripted"]
    assert "reach_door" in h.option_names and "reach_door" not in h.learnable
    assert h.child_mask()[0].tolist() == [False, False, True, True, True]


def test_flattening_is_one_level_over_the_leaves_deepest_first():
    env = KeyDoor()
    h = declare(env, "open_door", {"open_door": ["give_key", "reach_door", "use"],
                                   "give_key": ["primitives"]},
                success=_sat, policies={"give_key": lambda k, s, p, m: 0})
    flat = h.flattened()
    # give_key has children: replaced by them; reach_door is a leaf; primitives come first
    assert flat.option_names == ("open_door", "reach_door")
    assert flat.children == {"open_door": ("left", "right", "use", "reach_door")}
    assert flat.learnable == ("open_door",) and flat.stack_depth == 2
    assert flat.success is _sat and flat.policies == {}
    assert flat.flattened() == flat  # flattening is idempotent
    # without primitives anywhere, none are added
    deep = declare(env, "open_door", {"open_door": ["give_key", "reach_door"],
                                      "give_key": ["reach_door"]}).flattened()
    assert deep.children == {"open_door": ("reach_door",)} and deep.num_primitives == 0


@pytest.mark.parametrize("task", ["craft/get_gem", "craft/make_stick", "fetch/stack3",
                                  "football/11v11_easy"])
def test_every_catalogue_flat_is_its_default_hierarchys_flattening(task):
    import smjax

    env, _ = smjax.make(task)
    hierarchies = env.hierarchies()
    default = next(iter(hierarchies.values())).flattened()
    assert default.children == hierarchies["flat"].children
    assert default.option_names == hierarchies["flat"].option_names


@pytest.mark.parametrize("children, message", [
    ({"open_door": ["give_key", "jump"]}, "unknown child 'jump'"),
    ({"open_door": ["give_key"], "give_key": ["open_door_again"]}, "unknown child"),
    ({"give_key": ["primitives"]}, "declares no children for the task"),
    ({"open_door": []}, "empty list of children"),
    ({"open_door": "give_key"}, "must be a list of names"),
    ({"open_door": ["give_key"], "nosuch": ["left"]}, "unknown option 'nosuch'"),
])
def test_bad_declarations_name_the_culprit(children, message):
    with pytest.raises(HierarchyError, match=message):
        declare(KeyDoor(), "open_door", children)


def test_cycle_is_reported_with_its_path():
    a = OptionTemplate("a", _sat, 5, teleport=lambda k, s, p: (s, 0))
    b = OptionTemplate("b", _sat, 5, teleport=lambda k, s, p: (s, 0))
    with pytest.raises(HierarchyError, match="cycle: a -> b -> a"):
        Hierarchy("task", {"task": ["a"], "a": ["b"], "b": ["a"]}, {"a": a, "b": b}, ("x",))


def test_template_without_realisation_is_rejected():
    lonely = OptionTemplate("lonely", _sat, 5)
    with pytest.raises(HierarchyError, match="'lonely' has no way to be realised"):
        Hierarchy("task", {"task": ["lonely"]}, {"lonely": lonely}, ("x",))
    with pytest.raises(HierarchyError, match="'lonely' has neither a teleport nor a controller"):
        Hierarchy("task", {"task": ["lonely"], "lonely": ["x"]}, {"lonely": lonely}, ("x",))


def test_primitives_requested_without_discrete_actions():
    tpl = OptionTemplate("t", _sat, 5, controller=lambda k, s, p: 0)
    with pytest.raises(HierarchyError, match="no discrete primitive actions"):
        Hierarchy("task", {"task": ["t", "primitives"]}, {"t": tpl}, ())


def test_template_validation():
    with pytest.raises(ValueError, match="k_max must be >= 1"):
        OptionTemplate("t", _sat, 0)
    with pytest.raises(ValueError, match="non-empty"):
        OptionTemplate("", _sat, 3)
