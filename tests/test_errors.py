"""The error hierarchy: located messages (file, line, key) and the CLI's exit codes."""

from __future__ import annotations

import pickle

import pytest

from trafficsim import cli
from trafficsim.errors import (
    DataError,
    InputError,
    ScenarioError,
    ShipLibraryError,
    SimulationError,
    TrafficsimError,
)


@pytest.mark.parametrize("kwargs, expect", [
    ({"path": "a.yaml", "line": 12, "key": "ships.0.speed_kn"},
     "a.yaml:12: ships.0.speed_kn: too fast"),
    ({"path": "a.yaml", "key": "duration_s"}, "a.yaml: duration_s: too fast"),
    ({"path": "a.yaml", "line": 3}, "a.yaml:3: too fast"),
    ({"path": "a.yaml"}, "a.yaml: too fast"),
    ({"key": "--out"}, "--out: too fast"),
    ({}, "too fast"),
    # a line without a file cannot be located: it is left out
    ({"line": 7, "key": "k"}, "k: too fast"),
    # an empty key is no key
    ({"path": "p.csv", "key": ""}, "p.csv: too fast"),
    # line 0 is still a line number (only None means unknown)
    ({"path": "p.csv", "line": 0}, "p.csv:0: too fast"),
])
def test_render_places_file_line_and_key(kwargs, expect) -> None:
    """The documented layout ``file:line: key: message`` with each part optional."""
    err = InputError("too fast", **kwargs)
    assert err.render() == expect
    assert str(err) == expect
    assert err.message == "too fast"


def test_attributes_and_the_error_list() -> None:
    err = InputError("bad", path="f.yaml", line=2, key="x")
    assert (err.path, err.line, err.key) == ("f.yaml", 2, "x")
    assert err.errors == [err] and err.errors[0] is err


@pytest.mark.parametrize("cls", [InputError, ScenarioError, ShipLibraryError, DataError])
def test_input_errors_are_value_errors(cls) -> None:
    """Every leaf also inherits the matching built-in, so ``except ValueError`` catches it."""
    err = cls("m", path="p")
    assert isinstance(err, TrafficsimError) and isinstance(err, InputError)
    assert isinstance(err, ValueError) and not isinstance(err, RuntimeError)
    with pytest.raises(ValueError, match=r"^p: m$"):
        raise err


def test_simulation_error_is_a_runtime_error_not_an_input_error() -> None:
    err = SimulationError("ship 'a' diverged at step 3")
    assert isinstance(err, TrafficsimError) and isinstance(err, RuntimeError)
    assert not isinstance(err, InputError) and not isinstance(err, ValueError)
    assert str(err) == "ship 'a' diverged at step 3"


def test_message_survives_pickling() -> None:
    """Errors cross process boundaries (campaign workers): the rendered text is kept."""
    err = DataError("expected a number, got 'x'", path="run.csv", line=4, key="rpm")
    back = pickle.loads(pickle.dumps(err))
    assert isinstance(back, DataError) and str(back) == "run.csv:4: rpm: expected a number, got 'x'"


@pytest.mark.parametrize("exc, code", [
    (InputError("bad value", path="s.yaml", line=3, key="dt_s"), 2),
    (DataError("not a number", path="r.csv", line=9, key="rpm"), 2),
    (ShipLibraryError("unknown ship 'x'", key="--ship"), 2),
    (SimulationError("non-finite state of ship 'a' at step 12"), 1),
])
def test_cli_exit_codes_and_one_line(monkeypatch, capsys, exc, code) -> None:
    """The CLI turns an error into one stderr line with its location: code 2 for input
    errors, 1 for a diverged simulation (module doc)."""
    def boom(args):
        raise exc

    monkeypatch.setattr(cli, "_cmd_validate", boom)
    assert cli.main(["validate", "anything.yaml"]) == code
    err = capsys.readouterr().err
    assert err == f"trafficsim: error: {exc}\n"
