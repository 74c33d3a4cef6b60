"""Errors that the command line reports as bad input (exit code 2), in one line each."""

from __future__ import annotations


def one_line(text: str) -> str:
    """``text`` with every non-printable character (newlines, carriage returns, NUL, ...) escaped, so
    that a message quoting a user's key or value stays one line on any terminal."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


MAX_MESSAGE = 600  # characters of one error line; longer ones quote a huge value and are shortened


def shorten(text: str, limit: int = 60) -> str:
    """``text`` cut to about ``limit`` characters, saying how long it was (for echoing a user's value)."""
    if len(text) <= limit:
        return text
    keep = max(limit - 20, 10)
    return f"{text[:keep]}...{text[-8:]} ({len(text)} characters)"


def _bounded(text: str) -> str:
    text = one_line(text)
    if len(text) <= MAX_MESSAGE:
        return text
    return f"{text[:MAX_MESSAGE - 120]} ...[{len(text) - MAX_MESSAGE + 40} characters left out]... {text[-80:]}"


class InputError(Exception):
    """Bad input from the user: a config, an argument, an unreadable file.

    ``str(err)`` is the complete one-line message, e.g.
    ``configs/x.yaml:12:7: game.agents.0.cost: unknown name 'y' at column 5 of expression 'x + y'``.
    Control characters quoted from the input are escaped (:func:`one_line`), and a message that quotes a huge
    value is shortened to about ``MAX_MESSAGE`` characters. A message that tells the caller what to do next says
    it in Python (``force=True``); ``cli`` is the same message for the command line (``--force``), which prints it.
    """

    def __init__(self, *args: object, cli: str | None = None):
        if len(args) == 1 and isinstance(args[0], str):
            args = (_bounded(args[0]),)
        super().__init__(*args)
        self.cli = _bounded(cli) if cli is not None else str(self)


class ConfigError(InputError):
    """A config that cannot be loaded: YAML syntax, schema or semantic error.

    ``problems`` holds every message found (each ``file:line:column: field.path: message``);
    ``str(err)`` is the first one, followed by a count of the others (``cli``: the same, pointing to
    ``gnerun validate``).
    """

    def __init__(self, problems: list[str]):
        self.problems = [_bounded(p) for p in problems]
        first = self.problems[0] if self.problems else "invalid config"
        more = len(self.problems) - 1
        count = f" (and {more} more problem{'s' if more > 1 else ''}" if more else ""
        super().__init__(first + (f"{count}: all of them in the error's .problems)" if more else ""),
                         cli=first + (f"{count}: run `gnerun validate` for all)" if more else ""))


class Unavailable(Exception):
    """Something this machine lacks for the request (a graphics driver, a display, a viewer that starts).

    Reported as ``error: <message>`` with exit code 1: the input is fine, the environment is not.
    """


class WriteError(Unavailable):
    """A run's output could not be written (disk full, file too large, permissions changed mid-run).

    Reported like :class:`Unavailable` (exit code 1); what was flushed before stays readable.
    """
