"""``ndds.CsMat``: a named 2-D float64 array with row and column field names and units — the
CSMat of ControlShell, as ``ndds run`` systems publish and subscribe to it."""

from __future__ import annotations

from typing import Any, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

Field = Tuple[str, str]
FieldsArg = Optional[Iterable[Union[str, Tuple[str, str]]]]


def _fields(axis: str, given: FieldsArg, count: int) -> List[Field]:
    if given is None:
        return []
    fields: List[Field] = []
    for item in given:
        if isinstance(item, str):
            fields.append((item, ""))
        else:
            name, unit = item
            fields.append((str(name), str(unit)))
    if fields and len(fields) != count:
        raise ValueError(
            f"{axis} fields: {len(fields)} given for {count} {axis}s (give one per {axis}, or none)"
        )
    return fields


class CsMat:
    """A CSMat: ``array`` (2-D, float64), a ``name``, and per axis either no fields or one
    ``(name, unit)`` per row (column).

    The array is wrapped without a copy when it already is float64 (``numpy.asarray``); a
    received CSMat's array is a read-only view of the received bytes (``copy()`` it to change
    it). A 1-D array is a column (n × 1), as a CSMat vector is.

    >>> m = CsMat([[1.0], [2.0]], "x", rows=[("q1", "rad"), ("q2", "rad")])
    >>> m["q2"]
    2.0
    """

    __slots__ = ("array", "name", "row_fields", "col_fields")

    def __init__(
        self,
        array: Any,
        name: str = "",
        *,
        rows: FieldsArg = None,
        cols: FieldsArg = None,
    ) -> None:
        a = np.asarray(array, dtype=np.float64)
        if a.ndim == 0:
            a = a.reshape(1, 1)
        elif a.ndim == 1:
            a = a.reshape(-1, 1)
        elif a.ndim != 2:
            raise ValueError(f"a CsMat is 2-D; got an array of {a.ndim} dimensions")
        self.array: np.ndarray = a
        self.name: str = str(name)
        self.row_fields: List[Field] = _fields("row", rows, a.shape[0])
        self.col_fields: List[Field] = _fields("column", cols, a.shape[1])

    @property
    def shape(self) -> Tuple[int, int]:
        """``(rows, cols)``."""
        return self.array.shape  # type: ignore[return-value]

    @property
    def row_names(self) -> List[str]:
        return [f[0] for f in self.row_fields]

    @property
    def row_units(self) -> List[str]:
        return [f[1] for f in self.row_fields]

    @property
    def col_names(self) -> List[str]:
        return [f[0] for f in self.col_fields]

    @property
    def col_units(self) -> List[str]:
        return [f[1] for f in self.col_fields]

    def _index(self, key: Union[int, str], names: Sequence[str], axis: str) -> int:
        if isinstance(key, str):
            try:
                return list(names).index(key)
            except ValueError:
                raise KeyError(
                    f"{self.name or 'CsMat'} has no {axis} field {key!r} (fields: {', '.join(names) or 'none'})"
                ) from None
        return int(key)

    def __getitem__(self, key: Any) -> Any:
        """``m[i, j]`` or ``m["q1", "x"]`` by position or field name; ``m["q1"]`` (or ``m[i]``)
        is the row's entry of a one-column CsMat, else the row."""
        if isinstance(key, tuple):
            r, c = key
            return float(
                self.array[
                    self._index(r, self.row_names, "row"), self._index(c, self.col_names, "column")
                ]
            )
        row = self._index(key, self.row_names, "row")
        if self.array.shape[1] == 1:
            return float(self.array[row, 0])
        return self.array[row]

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        if copy:
            return np.array(self.array, dtype=dtype, copy=True)
        return self.array if dtype is None else self.array.astype(dtype)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CsMat):
            return NotImplemented
        return (
            self.name == other.name
            and self.row_fields == other.row_fields
            and self.col_fields == other.col_fields
            and self.array.shape == other.array.shape
            and bool(np.array_equal(self.array, other.array))
        )

    def __repr__(self) -> str:
        fields = ""
        if self.row_fields:
            fields += f", rows={self.row_fields!r}"
        if self.col_fields:
            fields += f", cols={self.col_fields!r}"
        return f"CsMat({self.array.tolist()!r}, {self.name!r}{fields})"

    # The wire: what the native module encodes and decodes.
    def _wire(self) -> Tuple[str, int, int, bytes, List[Field], List[Field]]:
        a = np.ascontiguousarray(self.array, dtype="<f8")
        rows, cols = a.shape
        return (self.name, rows, cols, a.tobytes(), self.row_fields, self.col_fields)

    @classmethod
    def _from_wire(
        cls,
        name: str,
        rows: int,
        cols: int,
        data: bytes,
        row_fields: List[Field],
        col_fields: List[Field],
    ) -> "CsMat":
        m = cls.__new__(cls)
        # A read-only view of the received bytes: no copy.
        m.array = np.frombuffer(data, dtype="<f8").reshape(rows, cols)
        m.name = name
        m.row_fields = list(row_fields)
        m.col_fields = list(col_fields)
        return m
