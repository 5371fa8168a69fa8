"""Issue 18's loose ends (stop 32's "noticed and left"): each a place where the tool said
something wrong or left a term out."""

from __future__ import annotations

import inspect

import align.plan_carried as plan_carried


def test_plan_carried_defaults_are_not_shared_mutable_objects():
    """``declared: Mapping = {}`` was one dict shared by every call: a caller that mutated what
    it got back (or a later edit of the function) would change every later call's default."""
    for name, f in inspect.getmembers(plan_carried, inspect.isfunction):
        if f.__module__ != plan_carried.__name__:
            continue
        for p in inspect.signature(f).parameters.values():
            assert not isinstance(p.default, (dict, list, set)), (name, p.name)
