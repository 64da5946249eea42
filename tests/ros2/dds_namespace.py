"""Tests of the ROS 2 node over real DDS, confined to a loopback-only network namespace.

Every process that opens DDS (the node, the player, the test's peer) runs inside one namespace made by
``unshare -n`` with only ``lo`` up and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``: the pytest process
itself never opens DDS. Without the ``ros2`` extra, or where no such namespace can be made (no user
namespaces, no ``unshare``), the tests are skipped with the reason.
"""

from __future__ import annotations

import importlib.util
import json
import shlex
import shutil
import subprocess
import sys
from functools import lru_cache
from pathlib import Path

import pytest

PEER = Path(__file__).with_name("peer.py")
DATA = Path(__file__).resolve().parents[1] / "data" / "robot_localization"


@lru_cache(maxsize=1)
def namespace_problem() -> str | None:
    """Why a loopback-only namespace cannot be made here (None: it can)."""
    if importlib.util.find_spec("rclpy") is None:
        return "the ros2 extra is not installed (pip install \"fusion-vo[ros2]\")"
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "unshare or ip is not installed: no loopback-only network namespace for DDS"
    probe = subprocess.run(["unshare", "-n", "sh", "-c", "ip link set lo up && ip -o link show | wc -l"],
                           capture_output=True, text=True)
    if probe.returncode != 0 or probe.stdout.strip() != "1":
        return f"cannot make a loopback-only network namespace ({(probe.stderr or probe.stdout).strip()[:200]})"
    return None


def in_namespace(argv: list[str]) -> list[str]:
    """``argv`` run in a new network namespace with only loopback, DDS discovery kept to this host."""
    return ["unshare", "-n", "sh", "-c",
            "ip link set lo up && export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST ROS_DOMAIN_ID=0 && exec "
            + shlex.join(argv)]


def run_peer(tmp_path: Path, spec: dict, timeout: float = 240.0) -> dict:
    """Run :mod:`peer` with ``spec`` inside the namespace and return what it recorded."""
    problem = namespace_problem()
    if problem:
        pytest.skip(problem)
    spec_path, out_path = tmp_path / "spec.json", tmp_path / "peer_out.json"
    spec_path.write_text(json.dumps(spec))
    proc = subprocess.run(in_namespace([sys.executable, str(PEER), str(spec_path), str(out_path)]),
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0 and out_path.exists(), proc.stderr[-3000:]
    return json.loads(out_path.read_text())

