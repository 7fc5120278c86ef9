"""Bad input gets help: the command line's parser (:class:`Parser`: one line, exit code 2, no
usage dump) with a "did you mean" for a mistyped subcommand, choice, flag or estimator name,
and ``--pixel -1,5`` read as a value (:func:`join_negative_values`), not as an unknown flag.

Plain Python and argparse; :mod:`ui.cli.common` re-exports all of it.
"""

from __future__ import annotations

import argparse
import difflib
import re
import sys

__all__ = ["CliError", "Parser", "did_you_mean", "estimator_names", "explain_estimator_error",
           "join_negative_values"]


class CliError(Exception):
    """A bad command line or input: printed as one ``psurf: error:`` line, exit code 2."""


def did_you_mean(word: str, choices) -> str:
    """``"; did you mean 'X'?"`` for the closest of ``choices`` to ``word`` ("" when none is
    close)."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


class Parser(argparse.ArgumentParser):
    """``ArgumentParser`` whose errors are :class:`CliError` (one line, exit 2, no usage),
    with a "did you mean" for a mistyped subcommand, choice or flag."""

    #: The top-level parser (set by the first parse_args), whose flags span every command.
    _top: Parser | None = None

    @classmethod
    def _top_options(cls) -> set:
        return cls._top.option_strings() if cls._top is not None else set()

    def option_strings(self) -> set:
        """Every flag of this parser and of its subcommands."""
        out = set(self._option_string_actions)
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    out |= (sub.option_strings() if isinstance(sub, Parser)
                            else set(sub._option_string_actions))
        return out

    #: The command line being parsed (a subcommand's error sees the whole of it).
    _argv: list = []

    def parse_args(self, args=None, namespace=None):  # noqa: D102 - argparse hook
        Parser._argv = list(sys.argv[1:] if args is None else args)
        Parser._top = self
        return super().parse_args(args, namespace)

    def error(self, message: str):  # noqa: D102 - argparse hook
        if message.startswith("the following arguments are required"):
            # A mistyped flag is the likelier cause: name it first.
            known = self.option_strings() | Parser._top_options()
            for tok in Parser._argv:
                flag = tok.split("=")[0]
                if flag.startswith("--") and flag not in known:
                    raise CliError(f"unrecognized argument {flag}"
                                   f"{did_you_mean(flag, sorted(known))}")
        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            choices = re.findall(r"'([^']*)'", m.group(2))
            message += did_you_mean(m.group(1), choices)
        m = re.match(r"unrecognized arguments: (\S+)", message)
        if m and m.group(1).startswith("-"):
            message += did_you_mean(m.group(1).split("=")[0], sorted(self.option_strings()))
        raise CliError(message)


def join_negative_values(argv: list) -> list:
    """``--pixel -1,5`` -> ``--pixel=-1,5``: a flag value that starts with ``-`` and a digit
    is glued to its flag, so argparse checks the value (one clear line) instead of taking it
    for an option ("expected one argument")."""
    out, i = [], 0
    argv = list(argv)
    while i < len(argv):
        tok = argv[i]
        if (tok.startswith("--") and "=" not in tok and i + 1 < len(argv)
                and re.match(r"^-\d", argv[i + 1])):
            out.append(f"{tok}={argv[i + 1]}")
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


def estimator_names() -> list[str]:
    """Every estimator name the parser knows (techniques, ``-short`` twins, presets)."""
    from psurf_core.estimators import PRESETS
    from psurf_core.techniques import REGISTRY

    names = ["reference", *REGISTRY, *PRESETS]
    names += [f"{n}-short" for n, e in REGISTRY.items() if e.has_short]
    return names


def explain_estimator_error(error: Exception) -> str:
    """The message of an estimator parse error, with a "did you mean" for a mistyped name
    (``unknown estimator 'paper-mutli'; did you mean 'paper-multi'?``)."""
    text = str(error)
    m = re.search(r"unknown estimator '([^']*)'", text)
    if m:
        return text + did_you_mean(m.group(1), estimator_names())
    m = re.search(r"'([^']*)' is not a member of '([^']*)'", text)
    if m:
        from psurf_core.estimators import parse_estimator

        try:
            members = [t.name for t in parse_estimator(m.group(2)).techniques]
        except Exception:
            members = []
        return text + did_you_mean(m.group(1), members)
    return text

