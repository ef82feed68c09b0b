"""How a flush turns buffered rows into Arrow columns."""

from __future__ import annotations

import pyarrow as pa
import pytest

from redrive.results._buffers import _array


@pytest.mark.parametrize(
    "values",
    [
        ("ok",) * 5,  # one value throughout: built as that value repeated
        ("",) * 3,
        ("ok", "error", "ok"),
        ("a", None),
        (None, "a"),
        (),
        ("é" * 40,) * 2,
    ],
)
def test_a_string_column_is_the_array_pa_array_makes(values: tuple[str | None, ...]) -> None:
    got, want = _array(values, pa.string()), pa.array(values, type=pa.string())
    assert got.type == want.type
    assert got.equals(want)
    assert got.null_count == want.null_count
    # the same buffers, byte for byte: the Parquet writer encodes the same file
    assert [b.to_pybytes() if b else None for b in got.buffers()] == [
        b.to_pybytes() if b else None for b in want.buffers()
    ]


def test_other_columns_are_converted_as_they_are() -> None:
    assert _array((1, 1, 1), pa.int64()).equals(pa.array([1, 1, 1], type=pa.int64()))
    assert _array((0.0, -0.0), pa.float64()).to_pylist() == [0.0, -0.0]
