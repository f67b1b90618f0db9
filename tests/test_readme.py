"""The README's two set-up commands are real: CI runs the second one verbatim."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _readme_commands():
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```bash\n# (\d)\. [^\n]*\n([^\n]+)\n```", text)
    return {number: command for number, command in blocks}


def test_readme_has_two_setup_commands():
    commands = _readme_commands()
    assert set(commands) == {"1", "2"}, f"README set-up blocks found: {sorted(commands)}"
    assert "visla-edu run sim" in commands["1"] and "--plot" in commands["1"]
    assert "pytest" in commands["2"]


def test_ci_runs_the_readme_test_command_verbatim():
    ci_lines = (ROOT / ".ci" / "run").read_text().splitlines()
    assert _readme_commands()["2"] in ci_lines, ".ci/run must run exactly the README's test command"


def test_the_readme_notebook_table_lists_every_notebook_with_its_points():
    """The README's hand-written table follows the notebooks' nbgrader metadata (as TEACHING.md's generated one)."""
    from visla_edu.course import release

    rows = re.findall(r"^\| `(\w+)` \| .* \| (\d+) \|$", (ROOT / "README.md").read_text(), flags=re.M)
    expected = [(path.stem, str(round(sum(points for _, points in release._graded_cells(release._read(path))))))
                for path in release._sources(ROOT / "solutions")]
    assert rows == expected
