"""``fusion-vo sweep`` given what a user can get wrong about it, each sweep as a user runs it: the sweeps
``test_command_faults.py`` checks.

``python tests/faults/sweep_faults_job.py FOLDER`` writes the fault tests' recording (``FOLDER/rec``), for each case
of :data:`SWEEPS` its grid file (``FOLDER/CASE.yaml``) and its sweep (``FOLDER/CASE``), each run by
``python -m fusion_vo.cli.main sweep ...`` in a fresh interpreter, and prints, as JSON, each case's grid file, exit
status, output and whether its ``results.csv`` was written. The session's second process runs it ahead
(tests/background.py); a test run without that process calls :func:`run_all` itself.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from fault_tools import make_pristine

#: case -> (the grid file's text, the options after ``--grid FILE``)
SWEEPS = {
    # ranking by a trajectory no run has (a misspelt name)
    "unknown_trajectory": ("grid: {fusion.max_gap: [0.25]}\n", ["--trajectory", "ekf_smothed"]),
    # 'random: 6' over two choices draws two distinct parameter sets
    "repeated_draws": ("random: 6\nseed: 0\nranges:\n  fusion.max_gap: [0.25, 0.5]\n", ["--no-evaluate"]),
}


def run_all(folder: Path) -> dict:
    """The recording and every case's sweep into ``folder`` (module docstring); returns what the job prints."""
    folder.mkdir(parents=True, exist_ok=True)
    rec = make_pristine(folder / "rec")
    out = {}
    for case, (text, options) in SWEEPS.items():
        grid = folder / f"{case}.yaml"
        grid.write_text(text)
        proc = subprocess.run([sys.executable, "-m", "fusion_vo.cli.main", "sweep", str(rec), "--out", str(folder / case),
                               "--grid", str(grid), "--workers", "1", "--no-dashboard", "--backend", "ekf", *options],
                              capture_output=True, text=True, timeout=300)
        out[case] = {"grid": str(grid), "code": proc.returncode, "stdout": proc.stdout, "stderr": proc.stderr,
                     "results": (folder / case / "results.csv").is_file()}
    return out


if __name__ == "__main__":
    print(json.dumps(run_all(Path(sys.argv[1]))))
