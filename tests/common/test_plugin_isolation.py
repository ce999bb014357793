"""Plugins are isolated: one that fails to load in any way, that would take a name already in
its table, or whose name cannot be named, is named in one warning line and left out; every
other entry of the table works, and naming the broken one raises its load error in one line."""

import sys
from importlib.metadata import EntryPoint

import pytest

import common.plugins
from common import Registry

GROUP = "test.isolated"


@pytest.fixture
def plugins(tmp_path, monkeypatch):
    """Install modules in a tmp folder on sys.path and the given entry points of ``GROUP``;
    warnings start afresh."""
    monkeypatch.setattr(common.plugins, "_warned", set(), raising=False)
    monkeypatch.syspath_prepend(str(tmp_path))
    added = []

    def install(modules: dict[str, str], *eps: tuple[str, str]):
        for name, text in modules.items():
            (tmp_path / f"{name}.py").write_text(text)
            added.append(name)
        points = [EntryPoint(n, v, GROUP) for n, v in eps]
        monkeypatch.setattr(
            common.plugins, "entry_points", lambda group: [e for e in points if e.group == group]
        )

    yield install
    for name in added:
        sys.modules.pop(name, None)


def _table():
    return Registry("thing", {"builtin": len}, entry_points=GROUP, error=LookupError)


def _warnings(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


@pytest.mark.parametrize(
    "body, shown",
    [
        ("raise ImportError('no module named torchvision_x')", "ImportError: no module named"),
        ("raise SystemExit(3)", "SystemExit: 3"),
        ("import sys\nsys.exit('plugin gave up')", "SystemExit: plugin gave up"),
        ("class Stop(BaseException): pass\nraise Stop('odd')", "Stop: odd"),
        ("1 / 0", "ZeroDivisionError: division by zero"),
    ],
)
def test_plugins_any_failure_at_import_is_named_and_skipped(plugins, capsys, body, shown):
    plugins(
        {"iso_bad_mod": body + "\n", "iso_good_mod": "def f(x):\n    return 2 * x\n"},
        ("bad", "iso_bad_mod:f"),
        ("good", "iso_good_mod:f"),
    )
    table = _table()
    assert table.names() == ["builtin", "good"] and table["good"](4) == 8
    assert table["builtin"]("ab") == 2 and "bad" not in table
    (line,) = _warnings(capsys)
    assert ": warning: thing plugin bad = iso_bad_mod:f failed to load (" in line
    assert shown in line and line.endswith("it is skipped")
    with pytest.raises(LookupError) as e:
        table["bad"]
    assert str(e.value).startswith("thing plugin bad = iso_bad_mod:f failed to load")
    assert shown in str(e.value) and "\n" not in str(e.value)


def test_plugins_keyboard_interrupt_at_import_is_not_swallowed(plugins):
    plugins({"iso_ctrl_c": "raise KeyboardInterrupt\n"}, ("ctrl_c", "iso_ctrl_c:f"))
    with pytest.raises(KeyboardInterrupt):
        _table().names()


def test_plugins_a_broken_plugin_is_warned_once_per_process(plugins, capsys):
    plugins({"iso_once": "raise ImportError('gone')\n"}, ("once", "iso_once:f"))
    first, second = _table(), _table()
    assert first.names() == second.names() == ["builtin"]
    second.load_entry_points(force=True)
    assert len(_warnings(capsys)) == 1
    with pytest.raises(LookupError, match="ImportError: gone"):
        second["once"]


def test_plugins_a_multi_line_error_stays_one_line(plugins, capsys):
    plugins({"iso_lines": "raise RuntimeError('first\\nsecond\\nthird')\n"}, ("ml", "iso_lines:f"))
    table = _table()
    assert table.names() == ["builtin"]
    (line,) = _warnings(capsys)
    assert "RuntimeError: first" in line and "second" not in line


def test_plugins_a_built_in_name_is_not_taken_silently(plugins, capsys):
    plugins({"iso_taker": "def f(x):\n    return 'plugin'\n"}, ("builtin", "iso_taker:f"))
    table = _table()
    assert table["builtin"] is len and not table.plugins and "iso_taker" not in sys.modules
    (line,) = _warnings(capsys)
    assert "thing plugin builtin = iso_taker:f is skipped" in line
    assert "built-in thing" in line and "kept" in line


def test_plugins_two_plugins_of_one_name_keep_the_first_and_name_the_second(plugins, capsys):
    plugins(
        {"iso_twin": "def a(x):\n    return 'a'\ndef b(x):\n    return 'b'\n"},
        ("twin", "iso_twin:a"),
        ("twin", "iso_twin:b"),
    )
    table = _table()
    assert table["twin"](0) == "a" and table.plugins == {"twin": "iso_twin:a"}
    (line,) = _warnings(capsys)
    assert "thing plugin twin = iso_twin:b is skipped" in line and "iso_twin:a" in line


@pytest.mark.parametrize("name", ["de:mo", "de,mo"])
def test_plugins_a_name_that_cannot_be_named_is_refused_at_registration(plugins, capsys, name):
    plugins({"iso_colon": "def f(x):\n    return x\n"}, (name, "iso_colon:f"))
    table = _table()
    assert table.names() == ["builtin"] and name not in table and not table.broken
    (line,) = _warnings(capsys)
    assert f"thing plugin {name} = iso_colon:f is refused" in line and "':' or ','" in line


def test_plugins_a_plugin_fixed_while_running_joins_on_a_reread(plugins, tmp_path, capsys):
    plugins({"iso_later": "raise ImportError('not yet')\n"}, ("later", "iso_later:f"))
    table = _table()
    assert "later" not in table and "later" in table.broken
    (tmp_path / "iso_later.py").write_text("def f(x):\n    return 'now'\n")
    table.load_entry_points(force=True)
    assert table["later"](0) == "now" and not table.broken
    assert len(_warnings(capsys)) == 1
