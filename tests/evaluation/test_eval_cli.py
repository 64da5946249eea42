"""The evaluate and compare commands, including their one-line errors."""

import json

from fusion_vo.cli.main import main

from eval_synthetic import make_run


def test_evaluate_prints_the_table_and_writes_the_report(tmp_path, capsys):
    run_dir, seq = make_run(tmp_path, with_frames=False)
    (run_dir / "run.yaml").write_text("frontend: features\n")  # no sequence named: --gt gives it
    assert main(["evaluate", str(run_dir), "--gt", str(seq)]) == 0
    out = capsys.readouterr().out
    assert "Position errors" in out and "wheel" in out and "Legs between turns" in out
    assert (run_dir / "report.html").is_file()
    assert not (run_dir / "frontend.png").exists()  # no velocities.csv, no frontend figure
    assert json.loads((run_dir / "metrics.json").read_text())["vo"]["heading_deg"] > 0


def test_evaluate_errors_name_the_file(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path / "nope")]) == 2
    assert "nope: run folder not found" in capsys.readouterr().err
    run_dir, seq = make_run(tmp_path, with_frames=False)
    (run_dir / "run.yaml").write_text("frontend: klt\n")
    assert main(["evaluate", str(run_dir)]) == 0  # no recording named: the report, without accuracy
    assert "note: run.yaml names no recording: no accuracy figures" in capsys.readouterr().out
    assert not (run_dir / "metrics.json").exists()
    assert main(["evaluate", str(run_dir), "--gt", str(tmp_path)]) == 2
    assert "recording has no ground truth" in capsys.readouterr().err
    with (run_dir / "wheel.tum").open("a") as f:
        f.write("99.0 1 2 3\n")
    assert main(["evaluate", str(run_dir), "--gt", str(seq)]) == 2
    err = capsys.readouterr().err
    assert "wheel.tum:" in err and "expected 8 columns" in err
    assert not (run_dir / "metrics.json").exists()


def test_compare_command(tmp_path, capsys):
    first, _ = make_run(tmp_path, name="klt", with_frames=False)
    second, _ = make_run(tmp_path, name="features", scale=0.97, with_frames=False)
    assert main(["compare", str(first), str(second), "--out", str(tmp_path / "cmp")]) == 0
    out = capsys.readouterr().out
    assert "klt / vo" in out and "features / ekf" in out
    assert (tmp_path / "cmp" / "compare.png").is_file()
