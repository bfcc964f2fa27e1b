"""``planner_service.settings``: a value read by its field's annotation, from TOML or from
``--set`` text, and a dataclass held to its fields' choices and bounds."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import pytest

from planner_service.settings import (Bound, SettingError, check_fields, read, read_fields, setting,
                                      split_assignment, toml_value)


@pytest.mark.parametrize("kind, raw, value", [
    (bool, True, True), (bool, "Yes", True), (bool, "on", True), (bool, "1", True), (bool, 1, True),
    (bool, "FALSE", False), (bool, "off", False), (bool, "0", False), (bool, "no", False),
    (int, 7, 7), (int, "7", 7), (int, " 12 ", 12), (int, 10.0, 10), (int, "1e3", 1000), (int, "-3", -3),
    (float, 2, 2.0), (float, "2.5", 2.5), (float, "1e-3", 0.001),
    (str, "tcp/a:1", "tcp/a:1"), (str, "", ""),
    (Literal["peer", "client"], "Client", "client"), (Literal[2, 3], "3", 3), (Literal[2, 3], 2, 2),
    (tuple[str, ...], "a, b,,c", ("a", "b", "c")), (tuple[str, ...], ["a"], ("a",)), (tuple[str, ...], "", ()),
    (tuple[float, ...], "[25, 50.5]", (25.0, 50.5)), (tuple[float, ...], "(1,2)", (1.0, 2.0)),
    (tuple[float, ...], [1, 2.5], (1.0, 2.5)), (tuple[str, ...], "tcp/[::1]:7447", ("tcp/[::1]:7447",)),
    (float | None, "none", None), (float | None, "", None), (float | None, None, None), (float | None, "4", 4.0),
    (str | None, "", ""), (str | None, None, None),
])
def test_a_value_is_read_by_its_type(kind: object, raw: object, value: object) -> None:
    got = read("x", kind, raw)
    assert got == value and type(got) is type(value)


@pytest.mark.parametrize("kind, raw, words", [
    (bool, "maybe", "cannot read 'maybe' as bool"), (bool, 2, "as bool"), (bool, 1.0, "as bool"),
    (int, "many", "cannot read 'many' as int"), (int, 10.5, "as int"), (int, True, "as int"), (int, "inf", "as int"),
    (float, "fast", "cannot read 'fast' as float"), (float, False, "as float"), (float, "nan", "must be finite"),
    (float, math.inf, "must be finite"), (str, 5, "cannot read 5 as str"),
    (Literal["peer", "client"], "broker", "'broker' is not one of ('peer', 'client')"),
    (Literal[2, 3], 4, "4 is not one of (2, 3)"), (Literal[2, 3], True, "is not one of"),
    (tuple[str, ...], 5, "cannot read 5 as a list"), (tuple[float, ...], "1,x", "cannot read 'x' as float"),
])
def test_a_bad_value_is_refused_with_its_name(kind: object, raw: object, words: str) -> None:
    with pytest.raises(SettingError) as err:
        read("section.key", kind, raw)
    assert err.value.name.startswith("section.key") and words in err.value.message
    if isinstance(raw, str) and "," in raw:
        assert err.value.name == "section.key[1]"  # the element, not only the list


@dataclass(frozen=True)
class Example:
    mode: Literal["a", "b"] = "a"
    rate_hz: float = setting(2.0, ge=1.0, unit="Hz")
    count: int = setting(3, gt=0)
    share: float = setting(0.5, ge=0, lt=1)
    items: int = setting(10, ge=3, le=20, why="three around the points")
    planes: tuple[float, ...] = (1.0,)

    def __post_init__(self) -> None:
        check_fields(self)


@pytest.mark.parametrize("changes, name, message", [
    ({"mode": "c"}, "mode", "'c' is not one of ('a', 'b')"),
    ({"rate_hz": 0.5}, "rate_hz", "must be at least 1 Hz, got 0.5"),
    ({"count": 0}, "count", "must be positive, got 0"),
    ({"share": 1.0}, "share", "must lie in [0, 1), got 1"),
    ({"items": 2}, "items", "must lie in [3, 20], got 2 (three around the points)"),
    ({"rate_hz": math.nan}, "rate_hz", "must be finite, got nan"),
    ({"planes": (1.0, math.inf)}, "planes[1]", "must be finite, got inf"),
])
def test_a_dataclass_is_held_to_its_fields(changes: dict, name: str, message: str) -> None:
    with pytest.raises(SettingError) as err:
        Example(**changes)
    assert (err.value.name, err.value.message) == (name, message)


def test_fields_read_by_name_and_unknown_names_refused() -> None:
    assert read_fields(Example, {"mode": "B", "count": "4", "planes": "2,3"}) == {
        "mode": "b", "count": 4, "planes": (2.0, 3.0)}
    with pytest.raises(SettingError) as err:
        read_fields(Example, {"cout": "4"}, lambda key: f"example.{key}")
    assert err.value.name == "example.cout" and "unknown key; expected one of ['count'," in err.value.message
    with pytest.raises(SettingError) as err:
        read_fields(Example, {"count": "x"}, lambda key: f"example.{key}")
    assert err.value.name == "example.count"


def test_toml_text_reads_back_to_the_same_values() -> None:
    import tomllib
    values = {"flag": False, "n": 3, "x": 0.1, "s": 'a "quoted" \\ text', "t": ("a", "b"), "f": (1.5, 2.0)}
    text = "\n".join(f"{k} = {toml_value(v)}" for k, v in values.items())
    back = tomllib.loads(text)
    kinds = {"flag": bool, "n": int, "x": float, "s": str, "t": tuple[str, ...], "f": tuple[float, ...]}
    assert {k: read(k, kinds[k], back[k]) for k in values} == values


def test_assignments_and_bounds_in_words() -> None:
    assert split_assignment(" speed_mps = 10 ") == ("speed_mps", "10")
    assert split_assignment("url=udpout:a:1=b") == ("url", "udpout:a:1=b")
    for bad in ("speed_mps", "=3"):
        with pytest.raises(SettingError):
            split_assignment(bad)
    assert Bound(ge=0).describe() == "must not be negative"
    assert Bound(gt=1, unit="s").describe() == "must be more than 1 s"
    assert Bound(le=5).describe() == "must be at most 5"
    assert Bound(gt=0, le=1).describe() == "must lie in (0, 1]"
