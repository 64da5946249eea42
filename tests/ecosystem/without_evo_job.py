"""``fusion-vo simulate``, ``run`` and ``evaluate`` as a user without the ``eval`` extra runs them: each in a fresh
interpreter in which ``import evo`` fails.

``python tests/ecosystem/without_evo_job.py FOLDER`` writes the recording (``FOLDER/rec``), the run
(``FOLDER/run``) and a copy of the run's report before ``evaluate`` rebuilt it (``FOLDER/report_after_run.html``), and
prints, as JSON, each command's exit status and output: what ``test_without_evo.py`` checks. The session's second
process runs it ahead (tests/background.py); a test run without that process calls :func:`run_all` itself.
"""

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

from evo_blocker import BLOCK_EVO

ROOT = Path(__file__).resolve().parents[2]

_SCRIPT = BLOCK_EVO + textwrap.dedent("""
    from fusion_vo.cli.main import main
    sys.exit(main(sys.argv[1:]))
""")


def cli(*args) -> dict:
    """``fusion-vo ARGS`` with evo blocked: exit status, standard output and error."""
    proc = subprocess.run([sys.executable, "-c", _SCRIPT, *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)
    return {"code": proc.returncode, "stdout": proc.stdout, "stderr": proc.stderr}


def run_all(folder: Path) -> dict:
    """The three commands into ``folder`` (module docstring); a command is not run after one that failed."""
    folder.mkdir(parents=True, exist_ok=True)
    rec, out = folder / "rec", folder / "run"
    steps = {"folder": str(folder)}
    steps["made"] = cli("simulate", str(rec), "--profile", "random", "--duration", "1", "-O", "width=320", "-O",
                        "height=180", "-O", "fu=210", "-O", "fv=210", "-O", "cu=159.5", "-O", "cv=89.5")
    if steps["made"]["code"] != 0:
        return steps
    steps["done"] = cli("-q", "run", str(rec), "--out", str(out), "--backend", "ekf")
    if steps["done"]["code"] != 0:
        return steps
    shutil.copyfile(out / "report.html", folder / "report_after_run.html")
    steps["again"] = cli("evaluate", str(out))
    return steps


if __name__ == "__main__":
    print(json.dumps(run_all(Path(sys.argv[1]))))
