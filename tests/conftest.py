from pathlib import Path

import pytest

from trafficsim import cli

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
SHARED = ROOT.parent / "shared"


@pytest.fixture
def root() -> Path:
    return ROOT


def error_line(capsys: pytest.CaptureFixture[str], argv: list) -> str:
    """Run the command line in this process on ``argv``: it must end with exit code 2 and one
    ``trafficsim: error:`` line (no traceback), which is returned."""
    assert cli.main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("trafficsim: error: ")
    return lines[0]
