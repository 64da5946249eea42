"""``fusion-vo compare`` into a file or a pipe writes every number in full, and the table as CSV."""

from __future__ import annotations

import csv
import json
import math
import re

from fault_tools import cli


def test_compare_off_a_terminal_cuts_no_number_and_writes_csv(pristine, tmp_path, capsys):
    status, _, err = cli(capsys, "run", pristine, "--out", tmp_path / "klt_with_default_options", "--backend", "ekf")
    assert status == 0, err
    status, out, err = cli(capsys, "compare", tmp_path / "klt_with_default_options", "--out", tmp_path / "cmp")
    assert status == 0, err
    assert "…" not in out
    table = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    rows = list(csv.DictReader((tmp_path / "cmp" / "compare.csv").open()))
    assert [(r["run"], r["trajectory"]) for r in rows] == [(k, n) for k, runs in table.items() for n in runs]
    for r in rows:
        figures = table[r["run"]][r["trajectory"]]
        assert float(r["ate_m"]) == figures["ate_m"]  # full precision, not the printed 4 decimals
        printed = re.search(rf"klt_with_default_options / {r['trajectory']}\s+([0-9.]+)", out)
        # the terminal table shows a column in millimetres when one of its values is under 1 cm
        scale, tol = (1000.0, 5e-4) if re.search(r"ATE mm", out) else (1.0, 5e-5)
        assert printed and math.isclose(float(printed.group(1)), figures["ate_m"] * scale, abs_tol=tol)
