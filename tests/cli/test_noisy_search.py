"""``rapt-plan generate --noisy-search``: its help, its store, and one-line refusals of what it cannot combine with."""

from pathlib import Path

from typer.testing import CliRunner

from planner.cli import app

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
runner = CliRunner()


def test_help_says_what_the_noisy_search_does_and_why():
    result = runner.invoke(app, ["generate", "--help"], env={"COLUMNS": "200"})
    text = " ".join(result.output.split())
    assert result.exit_code == 0 and "--noisy-search" in text
    assert "stochastic simulator" in text and "4.2.3" in text and "study-noisy.db" in text


def test_bad_combinations_are_one_line_errors_with_exit_code_2(tmp_path):
    mission = str(EXAMPLES / "range2017.toml")
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "study-noisy.db").write_bytes(b"")
    for extra, expect in [
        (["--out", str(tmp_path / "a"), "--refine"], "--noisy-search: searches the stochastic expert itself"),
        (["--out", str(tmp_path / "b"), "--surrogate", str(tmp_path / "s.npz")], "combined with --surrogate"),
        (["--out", str(taken)], "study-noisy.db already holds a study"),
    ]:
        result = runner.invoke(app, ["generate", mission, "--noisy-search", *extra], env={"COLUMNS": "300"})
        assert result.exit_code == 2, (extra, result.output)
        assert expect in result.output and "Traceback" not in result.output
        assert len([line for line in result.output.splitlines() if line.strip()]) == 1
    assert not (tmp_path / "b" / "s.npz").exists()  # refused before any surrogate is trained
