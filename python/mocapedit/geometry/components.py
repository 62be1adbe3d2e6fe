"""Connected components: a union-find (disjoint sets) over hashable items."""
from __future__ import annotations

from typing import Hashable, Iterable


class UnionFind:
    """Disjoint sets of hashable items, each named by its root item.

    ``union(a, b)`` makes the root of ``a``'s set the root of the joined set, so callers that
    want a canonical root (the smallest item, say) pass the roots in that order.
    """

    def __init__(self, items: Iterable[Hashable]):
        self.parent = {item: item for item in items}

    def find(self, item):
        """The root of ``item``'s set (halving the path on the way)."""
        parent = self.parent
        while parent[item] != item:
            parent[item] = parent[parent[item]]
            item = parent[item]
        return item

    def union(self, a, b) -> None:
        """Joins the sets of ``a`` and ``b`` under the root of ``a``'s."""
        root = self.find(a)
        self.parent[self.find(b)] = root

    def union_smallest(self, a, b) -> None:
        """Joins the sets of ``a`` and ``b`` under the smaller of their two roots."""
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self.parent[max(ra, rb)] = min(ra, rb)

    def sets(self, items: Iterable[Hashable]) -> dict:
        """root -> the members among ``items`` of its set, in the order given."""
        out: dict = {}
        for item in items:
            out.setdefault(self.find(item), []).append(item)
        return out
