"""Errors that the command line reports as bad input (exit code 2), in one line each."""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable


class Names:
    """Names to suggest from when a word is not one of them (:meth:`closest`). Names numbered by a family's index
    (``ux1 .. ux200``) are compared by their pattern (``ux#``), and the suggestion keeps the word's numbers: a misspelt
    ``uxx7`` is ``ux7``, in a game of 5 or of 5,000 agents, at the cost of comparing a few patterns."""

    def __init__(self, names: Iterable[str]):
        self.patterns: dict[str, dict[tuple[str, ...], str]] = {}  # 'ux#' -> {('7',): 'ux7', ...}
        for name in names:
            self.patterns.setdefault(_DIGITS.sub("#", name.lower()), {}).setdefault(
                tuple(_DIGITS.findall(name)), name)

    def closest(self, word: str) -> str | None:
        """The name closest to ``word``: of the pattern closest to the word's (difflib's ratio of at least 0.6, the case
        ignored), the name with the word's numbers; else (a word without numbers) a name that begins the word or that
        the word begins; or None."""
        low = word.lower()
        numbers = tuple(_DIGITS.findall(word))
        pattern = _DIGITS.sub("#", low)
        if numbers and pattern in self.patterns:  # a number out of the family's range is not a misspelling (x5: x1..x4)
            return None
        for close in difflib.get_close_matches(pattern, list(self.patterns), n=3):
            if numbers in self.patterns[close]:  # (the same answer for every copy: y2 and y10 are not x2 and x10)
                return self.patterns[close][numbers]
        if not numbers:  # an abbreviation or a longer form (tol for tolerance)
            for c, names in self.patterns.items():
                if min(len(c), len(low)) >= 3 and "#" not in c and (c.startswith(low) or low.startswith(c)):
                    return names[()]
        return None

    def suggestion(self, word: str) -> str:
        """``"; did you mean 'x'?"`` (:meth:`closest`), or ``""``."""
        close = self.closest(word)
        return f"; did you mean {close!r}?" if close is not None else ""


_DIGITS = re.compile(r"\d+")


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` for the choice closest to a misspelt ``word`` (:meth:`Names.closest`), or ``""`` when
    none is close."""
    return Names(choices).suggestion(word)


EXCERPT_WIDTH = 100  # characters of a source line shown under a message


def excerpt(line: str, number: int, column: int, length: int = 1) -> str:
    """The source ``line`` (its ``number``) and a caret line under ``length`` characters from ``column`` (1-based), as
    two lines to print under a message: ``  35 | text`` and ``     |      ^^^``. A line longer than
    :data:`EXCERPT_WIDTH` is cut to a window around the column."""
    line = one_line(line.rstrip("\r\n"))
    start = 0
    if len(line) > EXCERPT_WIDTH:
        start = max(0, min(column - 1 - EXCERPT_WIDTH // 2, len(line) - EXCERPT_WIDTH))
        line = ("..." if start else "") + line[start:start + EXCERPT_WIDTH] + (
            "..." if start + EXCERPT_WIDTH < len(line) else "")
        column -= start - (3 if start else 0)
    gutter = f"{number:>4} | "
    pad = "".join("\t" if c == "\t" else " " for c in line[:column - 1])
    return f"{gutter}{line}\n{' ' * (len(gutter) - 2)}| {pad}{'^' * max(1, length)}"


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

    ``problems`` holds every message found (each ``file:line:column: field.path: message``, one line, which may be
    followed by an :func:`excerpt` of the source: the line and a caret under the character);
    ``str(err)`` is the first one, followed by a count of the others (``cli``: the same, pointing to
    ``gnerun validate``).
    """

    def __init__(self, problems: list[str]):
        self.problems = [_problem(p) for p in problems]
        first, shown = split_excerpt(self.problems[0] if self.problems else "invalid config")
        more = len(self.problems) - 1
        count = f" (and {more} more problem{'s' if more > 1 else ''}" if more else ""
        super().__init__(first + (f"{count}: all of them in the error's .problems)" if more else ""),
                         cli=first + (f"{count}: run `gnerun validate` for all)" if more else ""))
        if shown:  # the excerpt's lines are already one line each
            self.args = (f"{self.args[0]}\n{shown}",)
            self.cli = f"{self.cli}\n{shown}"


def _problem(text: str) -> str:
    """A problem's message bounded to one line; an excerpt after it (lines made by :func:`excerpt`) kept."""
    head, shown = split_excerpt(text)
    return _bounded(head) + (f"\n{shown}" if shown else "")


_EXCERPT = re.compile(r"\n( {0,3}\d+ \| [^\n]*\n     \| [ \t]*\^+)$")


def split_excerpt(text: str) -> tuple[str, str]:
    """A message and the :func:`excerpt` of the source that ends it (``""`` if none): a newline elsewhere is the
    user's, quoted (and escaped when shown)."""
    m = _EXCERPT.search(text)
    return (text[:m.start()], m[1]) if m else (text, "")


class Unavailable(Exception):
    """Something this machine lacks for the request (a graphics driver, a display, a viewer that starts).

    Reported as ``error: <message>`` with exit code 1: the input is fine, the environment is not.
    """


class WriteError(Unavailable):
    """A run's output could not be written (disk full, file too large, permissions changed mid-run).

    Reported like :class:`Unavailable` (exit code 1); what was flushed before stays readable.
    """
