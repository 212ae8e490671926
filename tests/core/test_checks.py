"""The shape-check helper (brdfgan.core.checks): patterns that pass, each failure kind, the message."""

from __future__ import annotations

import doctest
import functools

import numpy as np
import pytest
import torch

import brdfgan.core.checks
from brdfgan.core.checks import check_shape
from brdfgan.errors import UserError


def test_docstring_example_runs() -> None:
    result = doctest.testmod(brdfgan.core.checks)
    assert result.attempted > 0
    assert result.failed == 0


@pytest.mark.parametrize(
    ("shape", "pattern", "bound"),
    [
        ((2, 8, 4, 5), "B 8 H W", {"B": 2, "H": 4, "W": 5}),
        ((8, 4, 5), "* 8 H W", {"H": 4, "W": 5}),
        ((2, 3, 8, 4, 5), "* 8 H W", {"H": 4, "W": 5}),
        ((3, 6, 6), "3 S S", {"S": 6}),
        ((5, 3), "L 3", {"L": 5}),
        ((), "", {}),
        ((4,), "*", {}),
    ],
)
def test_matching_shapes_pass_and_bind(shape: tuple[int, ...], pattern: str, bound: dict[str, int]) -> None:
    assert check_shape(torch.zeros(shape), pattern) == bound


def test_numpy_arrays_are_checked_too() -> None:
    assert check_shape(np.zeros((4, 8, 3)), "H W 3", name="image") == {"H": 4, "W": 8}
    with pytest.raises(ValueError, match=r"image must have shape \(H, W, 3\), got \(4, 8, 4\)"):
        check_shape(np.zeros((4, 8, 4)), "H W 3", name="image")


@pytest.mark.parametrize(
    ("shape", "pattern"),
    [
        ((8, 4, 5), "B 8 H W"),  # too few dimensions
        ((1, 2, 8, 4, 5), "B 8 H W"),  # too many dimensions
        ((4, 5), "* 8 H W"),  # too few even with any leading dimensions
        ((2, 7, 4, 5), "B 8 H W"),  # wrong integer size
        ((2, 7, 4, 5), "* 8 H W"),
        ((3, 6, 5), "3 S S"),  # a repeated name sees two sizes
    ],
)
def test_mismatches_raise_value_error(shape: tuple[int, ...], pattern: str) -> None:
    with pytest.raises(ValueError, match="must have shape"):
        check_shape(torch.zeros(shape), pattern)


def test_message_names_argument_pattern_and_actual_shape() -> None:
    with pytest.raises(ValueError) as info:
        check_shape(torch.zeros(2, 7, 4, 5), "* 8 H W", name="maps")
    assert str(info.value) == "maps must have shape (*, 8, H, W), got (2, 7, 4, 5)"


def test_dims_bind_names_in_advance_and_show_in_the_message() -> None:
    assert check_shape(torch.zeros(2, 3, 3), "B V 3", dims={"B": 2}) == {"B": 2, "V": 3}
    with pytest.raises(ValueError) as info:
        check_shape(torch.zeros(3, 3, 3), "B V 3", name="camera_position", dims={"B": 2})
    assert str(info.value) == "camera_position must have shape (2, V, 3), got (3, 3, 3)"


def test_error_class_is_the_callers() -> None:
    class BadInput(UserError):
        pass

    with pytest.raises(BadInput, match=r"photo must have shape \(3, H, W\), got \(4, 2, 2\)"):
        check_shape(torch.zeros(4, 2, 2), "3 H W", name="photo", error=BadInput)


def test_error_can_be_any_callable_that_makes_the_exception() -> None:
    class FileProblem(UserError):
        def __init__(self, path: str, problem: str) -> None:
            super().__init__(f"{path}: {problem}")

    with pytest.raises(FileProblem, match=r"^a\.raw: rgb must have shape \(H, W, 3\), got \(2, 2\)$"):
        check_shape(np.zeros((2, 2)), "H W 3", name="rgb", error=functools.partial(FileProblem, "a.raw"))


@pytest.mark.parametrize("pattern", ["B 8 * W", "B -1", "B 8.0", "(B, 8)"])
def test_malformed_pattern_is_a_value_error(pattern: str) -> None:
    with pytest.raises(ValueError, match="bad shape pattern"):
        check_shape(torch.zeros(1, 8), pattern)
