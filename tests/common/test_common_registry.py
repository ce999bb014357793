"""common.Registry: the one way every table of named things is declared."""

from importlib.metadata import EntryPoint

import pytest

import common.plugins
from common import Registry


def test_register_read_and_refuse():
    table = Registry[int]("thing", {"a": 1})
    table.register("b", 2)

    @table.register("c")
    def _c():
        return 3

    assert list(table) == ["a", "b", "c"] == table.names()
    assert table["b"] == 2 and "c" in table and "z" not in table and len(table) == 3
    assert dict(table.items())["a"] == 1
    with pytest.raises(KeyError, match=r"unknown thing 'z'; known: a, b, c"):
        table["z"]
    for bad in ("", "x:y", "x,y"):
        with pytest.raises(ValueError, match="thing name"):
            table.register(bad, 0)
    with pytest.raises(ValueError, match="'a' is already registered"):
        table.register("a", 9)
    with pytest.raises(TypeError):
        table["d"] = 4  # read-only: entries join through register


def test_check_refuses_an_entry():
    def positive(name, value):
        if value <= 0:
            raise TypeError(f"{name} must be positive")

    table = Registry[int]("count", check=positive)
    table.register("one", 1)
    with pytest.raises(TypeError, match="neg must be positive"):
        table.register("neg", -1)
    assert table.names() == ["one"]


def _fake_entry_points(monkeypatch, *eps):
    monkeypatch.setattr(
        common.plugins, "entry_points", lambda group: [e for e in eps if e.group == group]
    )


def test_entry_points_join_on_first_read_and_keep_built_ins(monkeypatch):
    _fake_entry_points(
        monkeypatch,
        EntryPoint("sqrt", "math:sqrt", "test.fns"),
        EntryPoint("abs", "math:fabs", "test.fns"),  # taken by a built-in: it keeps its entry
    )
    table = Registry("function", {"abs": abs}, entry_points="test.fns")
    assert table.names() == ["abs", "sqrt"]
    assert table["sqrt"](9.0) == 3.0 and table["abs"] is abs
    assert table.plugins == {"sqrt": "math:sqrt"}
    assert table.unregister("sqrt")(4.0) == 2.0 and "sqrt" not in table and not table.plugins
    table.load_entry_points()  # read once: an uninstalled plugin stays out
    assert "sqrt" not in table
    table.load_entry_points(force=True)  # read again: it is back
    assert table.plugins == {"sqrt": "math:sqrt"}


def test_a_broken_plugin_is_named_in_one_line(monkeypatch, capsys):
    """It is skipped with one warning line; the built-ins work; naming it raises its error."""
    monkeypatch.setattr(common.plugins, "_warned", set(), raising=False)
    _fake_entry_points(monkeypatch, EntryPoint("gone", "no_such_module_xyz:f", "test.broken"))
    table = Registry("function", {"abs": abs}, entry_points="test.broken", error=LookupError)
    assert table["abs"] is abs and table.names() == ["abs"] and "gone" not in table
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "function plugin gone = no_such_module_xyz:f failed" in err[0]
    with pytest.raises(LookupError, match=r"function plugin gone = no_such_module_xyz:f failed"):
        table["gone"]


def test_a_plugin_the_check_refuses_is_named(monkeypatch, capsys):
    monkeypatch.setattr(common.plugins, "_warned", set(), raising=False)
    _fake_entry_points(monkeypatch, EntryPoint("pi", "math:pi", "test.checked"))

    def callable_only(name, obj):
        if not callable(obj):
            raise TypeError("not callable")

    table = Registry("function", entry_points="test.checked", check=callable_only)
    assert table.names() == []
    assert "function plugin pi = math:pi is refused (not callable)" in capsys.readouterr().err
    with pytest.raises(ValueError, match=r"function plugin pi = math:pi is refused \(not call"):
        table["pi"]
