import pytest

from mocapedit.geometry import ground
from mocapedit.geometry.components import UnionFind


def test_union_keeps_the_first_sets_root():
    uf = UnionFind(range(6))
    uf.union(4, 1)
    uf.union(4, 5)
    assert uf.find(1) == uf.find(5) == 4
    assert uf.sets(range(6)) == {0: [0], 4: [1, 4, 5], 2: [2], 3: [3]}


def test_union_smallest_roots_each_set_at_its_smallest_item():
    uf = UnionFind(["c", "a", "d", "b"])
    uf.union_smallest("d", "b")
    uf.union_smallest("c", "d")
    uf.union_smallest("c", "b")       # already joined
    assert uf.sets(sorted("abcd")) == {"a": ["a"], "b": ["b", "c", "d"]}


def test_find_of_an_unknown_item_raises():
    with pytest.raises(KeyError):
        UnionFind(range(2)).find(7)


@pytest.mark.parametrize("up, plane", [("Y", (0, 2)), ("Z", (0, 1)), ("z", (0, 1))])
def test_plane_indices_are_the_ground_axes(up, plane):
    assert ground.plane_indices(up) == plane
    _, (iu, _), (iv, _) = ground.ground_axes(up)
    assert (iu, iv) == plane


def test_ground_helpers_reject_bad_shapes_and_axes():
    with pytest.raises(ValueError):
        ground.to_ground([[0.0, 1.0]], "Y")
    with pytest.raises(ValueError):
        ground.from_ground([[0.0, 1.0, 2.0]], 0.0, "Z")
    with pytest.raises(ValueError):
        ground.up_token("X")
