"""``fusion-vo --version`` names the package's version and the libraries its results depend on."""

from importlib.metadata import version

import pytest

import fusion_vo
from fusion_vo.cli.main import main


def test_version_line(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"fusion-vo {fusion_vo.__version__} (Python ")
    assert f"gtsam {version('gtsam')}" in lines[0] and f"numpy {version('numpy')}" in lines[0]


def test_package_and_distribution_versions_agree():
    assert fusion_vo.__version__ == version("fusion-vo")
