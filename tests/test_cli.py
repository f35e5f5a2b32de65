"""The `gevi` entry point: version, help, lazy imports, one-line errors."""
from __future__ import annotations

import subprocess
import sys

from gevi_cli import __version__
from support import run_cli


def test_version_and_help(capsys):
    code, out, _ = run_cli(["--version"], capsys)
    assert code == 0 and __version__ in out
    code, out, _ = run_cli(["--help"], capsys)
    assert code == 0
    for name in ("info", "convert"):
        assert name in out
    assert "Examples:" in out


def test_help_does_not_import_heavy_modules():
    code = ("import sys; from gevi_cli.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in ('numpy', 'cv2', 'evo', 'pandas', 'matplotlib') if m in sys.modules]\n"
            "print('HEAVY', heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "HEAVY []" in out


def test_usage_errors_are_one_line_exit_2(capsys):
    code, _, err = run_cli(["no-such-command"], capsys)
    assert code == 2 and err.startswith("gevi: error:") and err.strip().count("\n") == 0
    code, _, err = run_cli(["convert", "a.txt", "b.txt", "--to", "xyz"], capsys)
    assert code == 2 and "--to" in err and "Traceback" not in err


def test_debug_shows_traceback(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "gevi_cli.cli", "--debug", "info", str(tmp_path / "nope")],
                          capture_output=True, text=True)
    assert proc.returncode != 0 and "Traceback" in proc.stderr
