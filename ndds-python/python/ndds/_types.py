"""Sample types: Python type hints turned into the type description the Rust type of the same
shape gets, so Python and Rust endpoints of one topic match (same fingerprint).

=====================================  =============================================
Python                                 Rust
=====================================  =============================================
``bool``                               ``bool``
``int``                                ``i64``
``ndds.i8`` ... ``ndds.u64``           ``i8`` ... ``u64`` (``Annotated[int, ...]``)
``float``, ``ndds.f64``                ``f64``
``ndds.f32``                           ``f32``
``str``                                ``String``
``bytes``                              ``serde_bytes::ByteBuf`` (a byte string)
``list[ndds.u8]``                      ``Vec<u8>`` (``bytes`` values are accepted)
``list[T]``, ``tuple[T, ...]``         ``Vec<T>``
``tuple[A, B]``                        ``(A, B)``
``ndds.array(T, N)``                   ``[T; N]``
``Optional[T]``, ``T | None``          ``Option<T>``
``dict[K, V]``                         ``HashMap<K, V>`` / ``BTreeMap<K, V>``
a dataclass                            a struct with the same name and fields, in order
an ``enum.Enum``                       an enum of unit variants, same names, same order
=====================================  =============================================
"""

from __future__ import annotations

import collections.abc
import dataclasses
import enum
import sys
import typing
from typing import Any, Dict, List, Optional, Tuple

from . import _ndds

__all__ = [
    "i8", "i16", "i32", "i64", "u8", "u16", "u32", "u64", "f32", "f64", "array",
    "data_type",
]


class _Scalar:
    """Marks an ``int`` or ``float`` with the Rust scalar it is written as."""

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name

    def __repr__(self) -> str:
        return f"ndds.{self.name}"


class _Array:
    """Marks a ``list[T]`` as a fixed-size array ``[T; N]``."""

    __slots__ = ("length",)

    def __init__(self, length: int) -> None:
        self.length = length

    def __repr__(self) -> str:
        return f"ndds.array(..., {self.length})"


i8 = typing.Annotated[int, _Scalar("i8")]
i16 = typing.Annotated[int, _Scalar("i16")]
i32 = typing.Annotated[int, _Scalar("i32")]
i64 = typing.Annotated[int, _Scalar("i64")]
u8 = typing.Annotated[int, _Scalar("u8")]
u16 = typing.Annotated[int, _Scalar("u16")]
u32 = typing.Annotated[int, _Scalar("u32")]
u64 = typing.Annotated[int, _Scalar("u64")]
f32 = typing.Annotated[float, _Scalar("f32")]
f64 = float


def array(item: Any, length: int) -> Any:
    """A fixed-size array of ``length`` items of type ``item`` (Rust ``[T; N]``)."""
    if not isinstance(length, int) or length < 0:
        raise TypeError(f"array length must be an int >= 0, got {length!r}")
    return typing.Annotated[List[item], _Array(length)]  # type: ignore[valid-type]


_SCALARS = {bool: "bool", int: "i64", float: "f64", str: "str", bytes: "bytes", type(None): "unit"}

_NoneType = type(None)


class _Describer:
    """Walks one root type, collecting the named types (containers) it uses."""

    def __init__(self) -> None:
        self.containers: Dict[str, Tuple[str, str, list, Any]] = {}
        self.classes: Dict[str, Any] = {}

    def format(self, hint: Any, where: str) -> Any:
        origin = typing.get_origin(hint)
        args = typing.get_args(hint)
        if origin is typing.Annotated:
            base, *marks = args
            for mark in marks:
                if isinstance(mark, _Scalar):
                    return mark.name
                if isinstance(mark, _Array):
                    inner = typing.get_args(base)
                    if typing.get_origin(base) not in (list, List) or len(inner) != 1:
                        raise TypeError(f"{where}: ndds.array needs list[T]")
                    return ("array", self.format(inner[0], where + "[]"), mark.length)
            return self.format(base, where)
        if hint in _SCALARS:
            return _SCALARS[hint]
        if origin is typing.Union or (sys.version_info >= (3, 10) and origin is _union_type()):
            rest = [a for a in args if a is not _NoneType]
            if len(rest) == 1 and len(args) == 2:
                return ("option", self.format(rest[0], where))
            raise TypeError(
                f"{where}: {hint!r} is a union; only Optional[T] (T | None) has a Rust "
                "counterpart (use an enum.Enum or a dataclass per case)"
            )
        if origin in (list, List, collections.abc.Sequence) or hint is list:
            if not args:
                raise TypeError(f"{where}: list needs an item type (list[float])")
            return ("seq", self.format(args[0], where + "[]"))
        if origin in (tuple, Tuple):
            if len(args) == 2 and args[1] is Ellipsis:
                return ("seq", self.format(args[0], where + "[]"))
            if not args:
                raise TypeError(f"{where}: tuple needs item types (tuple[float, int])")
            return ("tuple", [self.format(a, f"{where}[{i}]") for i, a in enumerate(args)])
        if origin in (dict, Dict, collections.abc.Mapping):
            if len(args) != 2:
                raise TypeError(f"{where}: dict needs key and value types (dict[str, float])")
            return ("map", self.format(args[0], where + "{key}"), self.format(args[1], where + "{}"))
        if isinstance(hint, type) and issubclass(hint, enum.Enum):
            return ("named", self.enum(hint))
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            return ("named", self.struct(hint))
        if isinstance(hint, str) or isinstance(hint, typing.ForwardRef):
            raise TypeError(f"{where}: unresolved type name {hint!r}")
        shown = getattr(hint, "__qualname__", None) or repr(hint)
        prefix = "" if where in (shown, repr(hint)) else f"{where}: "
        if isinstance(hint, type) and hint.__module__ != "builtins":
            raise TypeError(
                f"{prefix}{shown} is a class but not a dataclass: add @dataclasses.dataclass "
                "(its fields, with their type hints, are the sample's)"
            )
        raise TypeError(
            f"{prefix}{shown} has no ndds type; use bool, int, float, str, bytes, ndds.u8 "
            "and the other widths, list, tuple, dict, Optional, dataclasses or enum.Enum"
        )

    def _claim(self, name: str, cls: Any) -> bool:
        """True if `name` is new; False if `cls` is already described under it."""
        known = self.classes.get(name)
        if known is None:
            self.classes[name] = cls
            return True
        if known is cls:
            return False
        raise TypeError(
            f"two types named {name} ({known.__module__}.{known.__qualname__} and "
            f"{cls.__module__}.{cls.__qualname__}) in one sample type: the type description "
            "names each type once, as Rust's does (rename one)"
        )

    def enum(self, cls: Any) -> str:
        name = cls.__name__
        if self._claim(name, cls):
            members = [member.name for member in cls]  # aliases are not variants
            if not members:
                raise TypeError(f"enum {name} has no members")
            self.containers[name] = (name, "enum", members, cls)
        return name

    def struct(self, cls: Any) -> str:
        name = cls.__name__
        if not self._claim(name, cls):
            return name
        # Reserve the name first: a recursive type refers to itself by name.
        self.containers[name] = (name, "struct", [], cls)
        try:
            hints = typing.get_type_hints(cls, include_extras=True)
        except Exception as err:  # NameError for unresolvable forward references
            raise TypeError(f"cannot read the type hints of {name}: {err}") from err
        fields = []
        keyword = False
        for field in dataclasses.fields(cls):
            keyword = keyword or bool(getattr(field, "kw_only", False))
            if not field.init:
                raise TypeError(
                    f"{name}.{field.name}: fields with init=False cannot be received "
                    "(samples are built with every field)"
                )
            fields.append((field.name, self.format(hints[field.name], f"{name}.{field.name}")))
        self.containers[name] = (name, "struct_kw" if keyword else "struct", fields, cls)
        return name


def _union_type() -> Any:
    import types

    return types.UnionType


def _root_name(hint: Any) -> str:
    """The name tools show for a root type (Rust's, where it has one)."""
    if isinstance(hint, type) and (dataclasses.is_dataclass(hint) or issubclass(hint, enum.Enum)):
        return hint.__name__
    names = {bool: "bool", int: "i64", float: "f64", str: "String", bytes: "ByteBuf"}
    if hint in names:
        return names[hint]
    return repr(hint).replace("typing.", "")


_cache: Dict[Any, Any] = {}


def data_type(hint: Any) -> Any:
    """The ndds DataType of a Python type (a dataclass, an enum, or any hint in the table of
    this module), cached per type."""
    if isinstance(hint, _ndds.DataType):
        return hint
    try:
        cached = _cache.get(hint)
    except TypeError:  # an unhashable hint
        cached = None
    if cached is not None:
        return cached
    from ._csmat import CsMat

    if hint is CsMat:
        result = _ndds.csmat_type(CsMat._from_wire)
    else:
        describer = _Describer()
        root = describer.format(hint, _root_name(hint))
        result = _ndds.declare_type(_root_name(hint), root, list(describer.containers.values()))
    try:
        _cache[hint] = result
    except TypeError:
        pass
    return result
