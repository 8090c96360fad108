"""benchmarks/pytest_cpu.py: the per-test CPU plugin writes a line per test, and its summary
ranks the tests by the CPU of their process and of the subprocesses they waited for."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "pytest_cpu.py"


def test_plugin_and_summary(tmp_path: Path) -> None:
    (tmp_path / "test_two.py").write_text(
        textwrap.dedent(
            """
            import subprocess, sys

            def test_spins_in_a_subprocess():
                code = (
                    "import time\\nt = time.process_time()\\n"
                    "while time.process_time() - t < 0.3: pass"
                )
                subprocess.run([sys.executable, "-c", code], check=True)

            def test_quick():
                pass
            """
        )
    )
    out = tmp_path / "cpu"
    env = {**os.environ, "PYTEST_CPU_DIR": str(out), "PYTHONPATH": str(ROOT / "benchmarks")}
    r = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "pytest_cpu", "-p", "no:cacheprovider",
         "-n", "0", "-c", os.devnull, "--rootdir", str(tmp_path), str(tmp_path)],
        capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    r = subprocess.run(
        [sys.executable, str(SCRIPT), str(out), "--top", "5"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    rows = [line for line in r.stdout.splitlines() if "test_two.py::" in line]
    assert "test_spins_in_a_subprocess" in rows[0] and "test_quick" in rows[1], r.stdout
    spin = [float(x) for x in rows[0].strip("|").split("|")[:2]]
    assert spin[1] >= 0.25 and spin[0] >= spin[1], rows[0]  # counted as the subprocess's
    assert r.stdout.startswith("2 tests: ")


def test_summary_of_an_empty_folder_says_what_to_do(tmp_path: Path) -> None:
    r = subprocess.run(
        [sys.executable, str(SCRIPT), str(tmp_path)], capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert f"no cpu-*.jsonl in {tmp_path}: run pytest with -p pytest_cpu first" in r.stderr
