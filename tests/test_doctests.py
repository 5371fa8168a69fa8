"""The examples in the public functions' docstrings run (scikit-image style): an example in a
docstring is a test, so none goes stale."""

from __future__ import annotations

import doctest

import pytest

import align

EXAMPLES = ["measure_image", "measure_log", "calibrate", "run_session"]


@pytest.mark.parametrize("name", EXAMPLES)
def test_the_docstring_example_runs(name):
    fn = getattr(align, name)
    tests = doctest.DocTestFinder().find(fn, name, globs={})
    examples = [t for t in tests if t.examples]
    assert examples, f"{name} has no example in its docstring"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for t in examples:
        runner.run(t)
    assert runner.failures == 0, f"{name}: {runner.failures} example(s) failed (see above)"
