"""The core library imports nothing under the GPL: evo (GPL-3.0) is only for the ``eval`` extra."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

from evo_blocker import BLOCK_EVO

ROOT = Path(__file__).resolve().parents[2]

#: packages whose every module must import without evo
CORE_PACKAGES = ["frontends", "fusion_vo.geometry", "fusion_vo.sensors", "fusion_vo.backends", "fusion_vo.recording",
                 "fusion_vo.calibration", "fusion_vo.simulation", "fusion_vo.export"]
#: single modules of the core (and the command line, which must start without evo)
CORE_MODULES = ["fusion_vo", "fusion_vo.config", "fusion_vo.odometry", "fusion_vo.measurements",
                "fusion_vo.pipeline", "fusion_vo.cli.main", "fusion_vo.evaluation", "fusion_vo.evaluation.plots",
                "fusion_vo.evaluation.report", "fusion_vo.evaluation.matches"]

_SCRIPT = BLOCK_EVO + textwrap.dedent("""
    import importlib, pkgutil
    packages, modules = {packages!r}, {modules!r}
    imported = []
    for name in packages:
        package = importlib.import_module(name)
        imported.append(name)
        for info in pkgutil.walk_packages(package.__path__, name + "."):
            importlib.import_module(info.name)
            imported.append(info.name)
    for name in modules:
        importlib.import_module(name)
        imported.append(name)
    leaked = sorted(m for m in sys.modules if m == "evo" or m.startswith("evo."))
    assert not leaked, leaked
    try:
        importlib.import_module("fusion_vo.evaluation.metrics")
    except ImportError:
        print("blocked-ok")
    print(len(imported))
""")


def test_core_imports_without_evo():
    script = _SCRIPT.format(packages=CORE_PACKAGES, modules=CORE_MODULES)
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.split()
    # the blocker works: the metrics module, which needs evo, failed to import
    assert lines[0] == "blocked-ok"
    assert int(lines[1]) > 50  # every module of the core packages was walked


def test_evo_is_only_an_extra():
    text = (ROOT / "pyproject.toml").read_text()
    core = text.split("dependencies = [", 1)[1].split("]", 1)[0]
    assert "evo" not in core
    extras = text.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    assert 'eval = ["evo' in extras
    assert (ROOT / "LICENSE").read_text().startswith("BSD 3-Clause License")


def _licence_texts(dist) -> str:
    meta = dist.metadata
    parts = [meta.get("License-Expression") or "", (meta.get("License") or "")[:200]]
    parts += [c for c in meta.get_all("Classifier") or [] if c.startswith("License")]
    return " ".join(parts)


def test_installed_core_dependencies_are_not_gpl():
    """Walk the installed dependency closure of the core (no extras): nothing in it is GPL."""
    from importlib.metadata import PackageNotFoundError, distribution

    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    seen: dict[str, str] = {}
    todo = ["fusion-vo"]
    while todo:
        name = canonicalize_name(todo.pop())
        if name in seen:
            continue
        try:
            dist = distribution(name)
        except PackageNotFoundError:  # an optional platform dependency that is not installed here
            seen[name] = ""
            continue
        seen[name] = _licence_texts(dist)
        for text in dist.requires or []:
            req = Requirement(text)
            if req.marker is None or req.marker.evaluate({"extra": ""}):
                todo.append(req.name)
    assert {"numpy", "gtsam", "rosbags", "pydantic", "jinja2", "mcap", "pymap3d"} <= set(seen)
    assert "evo" not in seen
    gpl = {name: text for name, text in seen.items()
           if "GPL" in text.replace("LGPL", "") or "General Public License" in text.replace("Lesser General", "")}
    assert not gpl, gpl
    # the walk does see a GPL licence where there is one
    assert "GPL" in _licence_texts(distribution("evo"))
