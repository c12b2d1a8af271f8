import platform
import re
from pathlib import Path

import llvmlite.binding
import pytest

from trafficsim import cli

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
SHARED = ROOT.parent / "shared"

#: skip a test that reads x86 AVX instructions off compiled code on a machine without them
requires_avx = pytest.mark.skipif(
    platform.machine() not in ("x86_64", "AMD64")
    or not llvmlite.binding.get_host_cpu_features().get("avx"), reason="x86 AVX instructions")


def packed_divisions(asm: str) -> bool:
    """Whether assembly holds divisions of four or eight doubles at once (ymm or zmm
    registers; two-wide ones can be scalar code paired, not a vectorised loop)."""
    return re.search(r"divpd\s[^\n]*%[yz]mm", asm) is not None


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
