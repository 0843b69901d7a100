"""The CLI run in-process for tests: `invoke` gives typer's result, `ok` asserts a clean exit, `one_line_error`
asserts the one-line refusal every bad input gets (exit 2, no traceback)."""

from __future__ import annotations

from typer.testing import CliRunner, Result

from neoslam.cli import app

__all__ = ["invoke", "ok", "one_line_error"]


def invoke(*args: object, env: dict[str, str] | None = None) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args], env=env)


def ok(*args: object, env: dict[str, str] | None = None) -> Result:
    result = invoke(*args, env=env)
    assert result.exit_code == 0, (result.output, result.exception)
    return result


def one_line_error(result: Result, *parts: str) -> str:
    """The error line, after checking it is the only line on stderr, names every part and came with exit code 2."""
    assert "Traceback" not in result.output, result.output
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    assert isinstance(result.exception, SystemExit), result.exception
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("neoslam: error: "), result.stderr
    for part in parts:
        assert part in lines[0], (part, lines[0])
    return lines[0]
