"""pytest: lpoe.calibrate's defaults and help are the option table's (lpoe/options.h), the table
lpoe_calibrate's flags are defined from: a literal default written in the bindings or in the tool
that differs from the table fails here."""
import inspect
import os
import re
import subprocess

import pytest

import lpoe

CLI = os.environ.get("LPOE_CALIBRATE")
# Keyword arguments whose Python default is None for "not given" (the docstring says so).
NONE_FOR_NOT_GIVEN = {"sigma", "fixed_tools"}


def table_value(entry, like):
    """The table's default text as the type of the Python default `like`."""
    text = entry["default"]
    if isinstance(like, bool):
        assert text in ("true", "false"), entry
        return text == "true"
    if isinstance(like, (int, float)):
        return type(like)(float(text))
    return text


def calibrate_keywords():
    params = inspect.signature(lpoe.calibrate).parameters
    return {n: p for n, p in params.items() if p.kind is inspect.Parameter.KEYWORD_ONLY}


def test_calibrate_defaults_and_help_come_from_the_option_table():
    table = {e["name"]: e for e in lpoe.options("lpoe_calibrate")}
    keywords = calibrate_keywords()
    # Every keyword argument but prior= (a file or an lpoe.Prior) is an option of the table.
    assert set(keywords) - {"prior"} <= set(table), set(keywords) - set(table)
    doc = " ".join(lpoe.calibrate.__doc__.split())
    for name, p in keywords.items():
        if name == "prior":
            continue
        entry = table[name]
        if name in NONE_FOR_NOT_GIVEN:
            assert p.default is None, name
        else:
            assert p.default == table_value(entry, p.default), (name, p.default, entry["default"])
            assert type(p.default) is type(table_value(entry, p.default)), name
        # The docstring states the table's help and range for each keyword.
        assert " ".join(entry["help"].split()) in doc, name
        if entry["range"]:
            assert f"{name}=" in doc and entry["range"] in doc, name
    # A few values as the README documents them (so the table itself cannot drift silently).
    assert keywords["outlier_threshold"].default == 5.0
    assert keywords["solver"].default == "linear" and keywords["register"].default is True
    assert table["max_iterations"]["range"] == "[1, 10000]"


def test_options_lists_a_tools_own_and_shared_options():
    names = [e["name"] for e in lpoe.options("lpoe_compensate")]
    assert "restarts" in names and "angle_unit" in names and "outlier_threshold" not in names
    threads = {e["scope"]: e for e in lpoe.options("lpoe_compensate") if e["name"] == "threads"}
    assert list(threads) == ["lpoe_compensate"]
    # A tool without options of its own has the shared ones only.
    assert {e["scope"] for e in lpoe.options("lpoe_predict")} == {""}


def gflags_help(text):
    """{flag: (help, default)} from a gflags --help listing."""
    out = {}
    for m in re.finditer(r"-(\w+) \((.*?)\)\s+type: \w+\s+default: (\"[^\"]*\"|\S+)", text, re.S):
        out[m.group(1)] = (" ".join(m.group(2).split()), m.group(3).strip('"'))
    return out


@pytest.mark.skipif(CLI is None, reason="LPOE_CALIBRATE (the built tool) not given")
def test_the_tools_flags_have_the_tables_defaults_and_help():
    run = subprocess.run([CLI, "--help"], capture_output=True, text=True)
    flags = gflags_help(run.stdout + run.stderr)
    assert len(flags) > 30
    for name, p in calibrate_keywords().items():
        if name == "prior":
            continue
        entry = next(e for e in lpoe.options("lpoe_calibrate") if e["name"] == name)
        help_text, default = flags[name]
        assert help_text == " ".join(entry["help"].split()), name
        if name in NONE_FOR_NOT_GIVEN:
            continue
        value = table_value(entry, p.default)
        if isinstance(value, bool):
            assert default == ("true" if value else "false"), name
        elif isinstance(value, (int, float)):
            assert float(default) == value, (name, default)
        else:
            assert default == value, name
