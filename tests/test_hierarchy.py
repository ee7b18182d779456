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
