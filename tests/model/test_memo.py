"""model.memo.Memo, the one "recompute when these inputs change" helper (issue 24, item 6)."""
import numpy as np
import pytest

from cdpr_control.model.memo import Memo


def test_computes_once_per_key_and_again_on_a_new_key():
    calls = []

    def compute(v):
        calls.append(v)
        return v * 2

    memo = Memo()
    assert memo(b"a", compute, 1) == 2
    assert memo(b"a", compute, 5) == 2          # the same key: the kept value, not computed
    assert memo(b"b", compute, 3) == 6
    assert calls == [1, 3]


def test_a_key_of_none_always_computes():
    calls = []
    memo = Memo()
    for i in range(3):
        memo(None, calls.append, i)
    assert calls == [0, 1, 2]


def test_clear_forgets_the_value():
    calls = []
    memo = Memo()
    memo(1, calls.append, "x")
    memo.clear()
    memo(1, calls.append, "y")
    assert calls == ["x", "y"]


def test_bytes_keys_tell_minus_zero_from_zero():
    """(the reason the callers key on the floats' bytes: -0.0 == 0.0 as floats)"""
    memo = Memo()
    a = memo(np.array([0.0]).tobytes(), lambda: "zero")
    b = memo(np.array([-0.0]).tobytes(), lambda: "minus zero")
    assert (a, b) == ("zero", "minus zero")


def test_read_only_marks_the_kept_arrays():
    memo = Memo(read_only=True)
    x, (y, z) = memo(1, lambda: (np.zeros(3), (np.ones(2), [0.0])))
    with pytest.raises(ValueError):
        x[0] = 1.0
    with pytest.raises(ValueError):
        y[0] = 1.0
    assert memo(1, lambda: None)[0] is x       # the same objects on a hit


def test_writeable_by_default():
    x = Memo()(1, np.zeros, 3)
    x[0] = 1.0
    assert x[0] == 1.0
