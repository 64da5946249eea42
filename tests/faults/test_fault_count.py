"""The README quotes the number of ways the fault suite breaks a recording or its configuration."""

import re
from pathlib import Path

import test_config_faults
import test_recording_faults


def test_the_readme_quotes_the_suites_count_of_fault_kinds():
    recording = len(test_recording_faults.FAULTS) + len(test_recording_faults.PHYSICAL_RANGE_FAULTS)
    out_of_range, fusion = len(test_config_faults.OUT_OF_RANGE), len(test_config_faults.FUSION_BAD)
    text = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    quoted = re.search(r"in (\d+) ways \((\d+) recording faults, (\d+) out-of-range values, (\d+) further fusion", text)
    assert quoted, "README.md no longer quotes the fault suite's count"
    assert [int(g) for g in quoted.groups()] == [recording + out_of_range + fusion, recording, out_of_range, fusion]
