"""Settings: frozen dataclasses whose fields are read, by their annotations, from TOML or from
``--set name=value`` text, and checked beside their declarations.

One mechanism for the scenario (``model/scenario.py``) and every section of the service's
configuration (``service/config.py``), so that both accept the same values:

- ``bool``: a TOML boolean, or the text ``true/false``, ``1/0``, ``yes/no``, ``on/off`` (any case);
- ``int``: a whole number (``10``, ``10.0``, ``1e3``), never a boolean;
- ``float``: a finite number;
- ``str``: text, as given;
- ``Literal[...]``: one of the choices (text matched without regard to case);
- ``tuple[T, ...]``: a TOML array, or comma-separated text (brackets around it allowed),
  each element read as ``T``;
- ``T | None``: None, or a ``T`` (the text ``none`` or nothing stands for None, except for
  text fields, where only None is None).

A field's bound sits beside it: ``speed_mps: float = setting(20.0, gt=0)``, with its unit
and the reason when it is not obvious. ``check_fields`` holds an instance to its fields'
choices, finiteness and bounds (a dataclass calls it from ``__post_init__``, so a value
built in code is held to the same rules as one read from a file); rules that tie fields
together stay in the dataclass's own ``check``. Errors are ``SettingError(name, message)``;
each owner wraps them in its own exception type with its own key (``scenario.speed_mps``,
``zenoh.mode``).

This module imports nothing of the project: every layer may use it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import types
import typing
from dataclasses import dataclass
from typing import Any, Callable, Literal, Mapping

TRUE_WORDS = ("true", "1", "yes", "on")
FALSE_WORDS = ("false", "0", "no", "off")
NONE_WORDS = ("", "none")


class SettingError(ValueError):
    """A value was refused; ``name`` is the field (or ``name[i]`` for an element)."""

    def __init__(self, name: str, message: str) -> None:
        super().__init__(f"{name}: {message}")
        self.name = name
        self.message = message


@dataclass(frozen=True)
class Bound:
    """The range a number must lie in (any of the four limits may be absent)."""

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    unit: str = ""
    """Shown after the limits (``Hz``, ``m``, ``s``)."""
    why: str = ""
    """Why this bound, when the field's docstring does not already say."""

    def holds(self, value: float) -> bool:
        return ((self.ge is None or value >= self.ge) and (self.gt is None or value > self.gt)
                and (self.le is None or value <= self.le) and (self.lt is None or value < self.lt))

    def describe(self) -> str:
        """``must lie in [0.5, 50] m``, ``must be positive``, ``must be at least 1 Hz`` ..."""
        unit = f" {self.unit}" if self.unit else ""
        low = self.ge if self.ge is not None else self.gt
        high = self.le if self.le is not None else self.lt
        if low is not None and high is not None:
            left = "[" if self.ge is not None else "("
            right = "]" if self.le is not None else ")"
            text = f"must lie in {left}{low:g}, {high:g}{right}{unit}"
        elif self.gt == 0:
            text = "must be positive"
        elif self.ge == 0:
            text = "must not be negative"
        elif self.ge is not None:
            text = f"must be at least {self.ge:g}{unit}"
        elif self.gt is not None:
            text = f"must be more than {self.gt:g}{unit}"
        elif self.le is not None:
            text = f"must be at most {self.le:g}{unit}"
        elif self.lt is not None:
            text = f"must be less than {self.lt:g}{unit}"
        else:
            text = "any number"
        return text


def setting(default: Any, *, ge: float | None = None, gt: float | None = None, le: float | None = None,
            lt: float | None = None, unit: str = "", why: str = "") -> Any:
    """A dataclass field with ``default`` and a bound checked by ``check_fields``."""
    return dataclasses.field(default=default, metadata={"bound": Bound(ge, gt, le, lt, unit, why)})


# --- reading a value by its annotation ------------------------------------------------------

def read(name: str, kind: Any, raw: Any) -> Any:
    """``raw`` (a TOML value, a ``--set`` text, or a value already typed) as ``kind``, the
    field's annotation; ``SettingError(name, ...)`` when it cannot be."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin is Literal:
        return _read_choice(name, args, raw)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        if len(inner) != 1:
            raise TypeError(f"{name}: only T | None unions are settings, not {kind}")
        if raw is None or (inner[0] is not str and isinstance(raw, str) and raw.strip().lower() in NONE_WORDS):
            return None
        return read(name, inner[0], raw)
    if origin is tuple:
        if len(args) != 2 or args[1] is not Ellipsis:
            raise TypeError(f"{name}: only tuple[T, ...] is a setting, not {kind}")
        return _read_tuple(name, args[0], raw)
    if kind is bool:
        return _read_bool(name, raw)
    if kind is int:
        return _read_int(name, raw)
    if kind is float:
        return _read_float(name, raw)
    if kind is str:
        if not isinstance(raw, str):
            raise SettingError(name, f"cannot read {raw!r} as str: write it in quotes")
        return raw
    raise TypeError(f"{name}: {kind} is not a setting type")


def _read_bool(name: str, raw: Any) -> bool:
    if isinstance(raw, bool):
        return raw
    text = str(raw).strip().lower()
    if text in TRUE_WORDS:
        return True
    if text in FALSE_WORDS:
        return False
    raise SettingError(name, f"cannot read {raw!r} as bool: write true or false")


def _read_int(name: str, raw: Any) -> int:
    if isinstance(raw, int) and not isinstance(raw, bool):
        return raw
    number = math.nan
    if isinstance(raw, str):
        try:
            return int(raw.strip())
        except ValueError:
            try:
                number = float(raw.strip())  # 10.0 or 1e3: whole numbers all the same
            except ValueError:
                pass
    elif isinstance(raw, float):
        number = raw
    if not (math.isfinite(number) and number.is_integer()):
        raise SettingError(name, f"cannot read {raw!r} as int")
    return int(number)


def _read_float(name: str, raw: Any) -> float:
    if isinstance(raw, bool):
        raise SettingError(name, f"cannot read {raw!r} as float")
    try:
        number = float(raw.strip()) if isinstance(raw, str) else float(raw)
    except (TypeError, ValueError):
        raise SettingError(name, f"cannot read {raw!r} as float") from None
    if not math.isfinite(number):
        raise SettingError(name, f"must be finite, got {raw!r}")
    return number


def _read_choice(name: str, choices: tuple[Any, ...], raw: Any) -> Any:
    if isinstance(raw, str):
        text = raw.strip()
        for choice in choices:
            if isinstance(choice, str) and choice.lower() == text.lower():
                return choice
            if isinstance(choice, int) and not isinstance(choice, bool) and text == str(choice):
                return choice
    elif raw in choices and not isinstance(raw, bool):
        return next(c for c in choices if c == raw)
    raise SettingError(name, f"{raw!r} is not one of {choices}")


def _read_tuple(name: str, kind: Any, raw: Any) -> tuple[Any, ...]:
    if isinstance(raw, str):
        text = raw.strip()
        if text[:1] + text[-1:] in ("[]", "()"):
            text = text[1:-1]
        parts: list[Any] = [part.strip() for part in text.split(",") if part.strip()]
    elif isinstance(raw, (list, tuple)):
        parts = list(raw)
    else:
        raise SettingError(name, f"cannot read {raw!r} as a list: write [a, b] or a,b")
    return tuple(read(f"{name}[{i}]", kind, part) for i, part in enumerate(parts))


# --- a dataclass of settings ----------------------------------------------------------------

@functools.cache
def kinds(cls: type) -> dict[str, Any]:
    """Field name -> its annotation, resolved (``from __future__ import annotations`` leaves text)."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def read_fields(cls: type, values: Mapping[str, Any], where: Callable[[str], str] = str) -> dict[str, Any]:
    """``values`` (name -> raw) read by ``cls``'s annotations; an unknown name is refused with
    the known ones. ``where(name)`` is the key an error names (``zenoh.mode``)."""
    known = kinds(cls)
    out: dict[str, Any] = {}
    for name, raw in values.items():
        if name not in known:
            raise SettingError(where(name), f"unknown key; expected one of {sorted(known)}")
        try:
            out[name] = read(name, known[name], raw)
        except SettingError as err:
            raise SettingError(where(err.name), err.message) from None
    return out


def check_fields(obj: Any) -> None:
    """Hold every field of the dataclass ``obj`` to its annotation's choices, finiteness and
    bound; ``SettingError(name, ...)`` names the first that breaks one."""
    bounds = {f.name: f.metadata.get("bound") for f in dataclasses.fields(obj)}
    for name, kind in kinds(type(obj)).items():
        value = getattr(obj, name)
        _check_value(name, kind, value)
        bound = bounds[name]
        if bound is not None and isinstance(value, numbers.Real) and not bound.holds(value):
            why = f" ({bound.why})" if bound.why else ""
            raise SettingError(name, f"{bound.describe()}, got {value:g}{why}")


def _check_value(name: str, kind: Any, value: Any) -> None:
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin is Literal:
        if value not in args or isinstance(value, bool):
            raise SettingError(name, f"{value!r} is not one of {args}")
    elif origin in (typing.Union, types.UnionType):
        if value is not None:
            _check_value(name, next(a for a in args if a is not type(None)), value)
    elif origin is tuple and isinstance(value, tuple):
        for i, element in enumerate(value):
            _check_value(f"{name}[{i}]", args[0], element)
    elif kind is float and isinstance(value, float) and not math.isfinite(value):
        raise SettingError(name, f"must be finite, got {value}")


def toml_value(value: Any) -> str:
    """``value`` as TOML text (what ``read`` reads back to the same value)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return repr(value)


def split_assignment(item: str) -> tuple[str, str]:
    """``"name = value"`` -> (``name``, ``value``), both stripped; ``SettingError`` otherwise."""
    key, sep, value = item.partition("=")
    if not sep or not key.strip():
        raise SettingError(item, f"{item!r} is not of the form name=value")
    return key.strip(), value.strip()
