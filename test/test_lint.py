"""Lint with ruff (ruff.toml: 99 columns, single quotes), as the ament linters cannot run here."""
import pathlib
import subprocess
import sys

REPO = pathlib.Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    ruff = pathlib.Path(sys.executable).parent / 'ruff'
    run = subprocess.run([str(ruff), 'check', '--no-cache', '.'], cwd=REPO,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]
