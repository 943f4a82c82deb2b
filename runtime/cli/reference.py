"""The commands reference (docs/commands.md), written from the argparse definitions themselves.

The hand-written docs show what a user does; this page lists every command, sub-benchmark and option
with its help, so that no option is documented twice and none is missing. ``make docs`` regenerates it
(``python -m facepuppet.runtime.cli.reference docs/commands.md``) and ``tests/test_readme.py`` fails
when the committed page is not what this module writes now.

The text is built here rather than by argparse's ``HelpFormatter``, whose layout depends on the
terminal's width and on the Python version: the same parser gives the same page on every machine.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from facepuppet.runtime.bench.registry import bench_parser, benches
from facepuppet.runtime.cli import build_parser
from facepuppet.runtime.files.outputs import write_atomic

HEADER = """\
# Commands reference

<!-- Written by `make docs` from the argparse definitions (runtime/cli/reference.py): do not edit. -->

Every command of `facepuppet`, in the order `facepuppet --help` lists them, with each option's help.
`python -m facepuppet` is the same command. What the commands are for, with examples, is in the other
pages of [docs/](.) and in the [README](../README.md).
"""


def reference() -> str:
    """The whole page as Markdown: the top-level command, then each subcommand (``bench``'s benchmarks
    after it)."""
    parser = build_parser()
    commands = _subcommands(parser)
    lines = [HEADER, "| command | what it does |", "|---|---|"]
    lines += [f"| [`{name}`](#{anchor(sub.prog)}) | {_inline(summary)} |" for name, (sub, summary) in commands.items()]
    lines.append("")
    lines += section(parser, "")
    for sub, summary in commands.values():
        lines += section(sub, summary)
        if sub.prog == f"{parser.prog} bench":
            for bench in benches().values():
                lines += section(bench_parser(bench), bench.help, level="###")
    return "\n".join(lines).rstrip("\n") + "\n"


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, tuple[argparse.ArgumentParser, str]]:
    """name -> (parser, one-line help) of each subcommand, in the order the parser lists them."""
    found: dict[str, tuple[argparse.ArgumentParser, str]] = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {choice.dest: choice.help or "" for choice in action._choices_actions}
            for name, sub in action.choices.items():
                found[name] = (sub, helps.get(name, ""))
    return found


def section(parser: argparse.ArgumentParser, summary: str, level: str = "##") -> list[str]:
    """The lines of one command's part of the page: heading, summary and description, synopsis, and its
    options group by group."""
    lines = [f"{level} {parser.prog}", ""]
    for text in (summary, parser.description):
        if text and _flat(text) not in lines:
            lines += [_flat(text), ""]
    lines += ["```", _synopsis(parser), "```", ""]
    for group in parser._action_groups:
        # a subcommand choice is listed by the table at the top, not as an option
        actions = [a for a in group._group_actions if _shown(a) and not isinstance(a, argparse._SubParsersAction)]
        if not actions:
            continue
        lines.append(f"**{group.title}**" + (f": {_flat(group.description)}" if group.description else ""))
        lines.append("")
        lines += [_option_line(parser, a) for a in actions]
        lines.append("")
    if parser.epilog:
        lines += [_flat(parser.epilog), ""]
    return lines


def _shown(action: argparse.Action) -> bool:
    """Every option but ``-h`` (the same on every command) and those argparse itself hides."""
    return action.help is not argparse.SUPPRESS and not isinstance(action, argparse._HelpAction)


def _synopsis(parser: argparse.ArgumentParser) -> str:
    """``prog``, its required options and its positionals; ``[options]`` stands for the rest."""
    parts = [parser.prog]
    in_required_group = set()
    for group in parser._mutually_exclusive_groups:
        if group.required:
            members = [a for a in group._group_actions if _shown(a)]
            in_required_group.update(members)
            parts.append("(" + " | ".join(_invocation(a) for a in members) + ")")
    optionals = [a for a in parser._actions if a.option_strings and _shown(a) and a not in in_required_group]
    parts += [_invocation(a) for a in optionals if a.required]
    if any(not a.required for a in optionals):
        parts.append("[options]")
    for action in parser._actions:
        if not action.option_strings and _shown(action):
            parts.append(_args(action, action.dest))
    return " ".join(p for p in parts if p)


def _invocation(action: argparse.Action) -> str:
    """``--name METAVAR`` with the longest spelling, as a synopsis shows one option."""
    flag = max(action.option_strings, key=len)
    args = _args(action, action.dest.upper())
    return f"{flag} {args}" if args else flag


def _option_line(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    if action.option_strings:
        args = _args(action, action.dest.upper())
        spelled = ", ".join(action.option_strings) + (f" {args}" if args else "")
    else:
        spelled = _args(action, action.dest)
    notes = " (required)" if action.required and action.option_strings else ""
    text = _inline(_help(parser, action))
    return f"- `{spelled}`{notes}" + (f": {text}" if text else "")


def _args(action: argparse.Action, default: str) -> str:
    """The arguments an action takes, spelled as argparse's usage spells them."""
    if action.nargs == 0:
        return ""
    if action.metavar is not None:
        metavar = action.metavar
    elif action.choices is not None:
        metavar = "{" + ",".join(str(c) for c in action.choices) + "}"
    else:
        metavar = default
    names = list(metavar) if isinstance(metavar, tuple) else None

    def one(i: int = 0) -> str:
        return names[i] if names else str(metavar)

    nargs = action.nargs
    if nargs is None:
        return one()
    if nargs == argparse.OPTIONAL:
        return f"[{one()}]"
    if nargs == argparse.ZERO_OR_MORE:
        return f"[{one()} ...]"
    if nargs == argparse.ONE_OR_MORE:
        return f"{one()} [{one(1 if names and len(names) > 1 else 0)} ...]"
    if nargs == argparse.REMAINDER:
        return "..."
    if nargs == argparse.PARSER:
        return f"{one()} ..."
    if isinstance(nargs, int):
        return " ".join(one(i if names else 0) for i in range(nargs))
    return one()


def _help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The help text with argparse's ``%(default)s``-style fields filled in, as ``--help`` shows it."""
    if not action.help:
        return ""
    params = {k: v for k, v in vars(action).items() if v is not argparse.SUPPRESS}
    params["prog"] = parser.prog
    for key, value in list(params.items()):
        if hasattr(value, "__name__"):
            params[key] = value.__name__
    if params.get("choices") is not None:
        params["choices"] = ", ".join(str(c) for c in params["choices"])
    return _flat(action.help % params)


def _flat(text: str) -> str:
    """Whitespace collapsed, as argparse's default formatter collapses it."""
    return " ".join(text.split())


def _inline(text: str) -> str:
    """Help text as literal Markdown: outside its `code` spans an asterisk, an angle bracket or a bar is
    not emphasis, a tag or a table cell."""
    pieces = re.split(r"(`[^`]*`)", text)
    return "".join(p if p.startswith("`") else re.sub(r"([*<>|])", r"\\\1", p) for p in pieces)


def anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, spaces to hyphens, other punctuation dropped."""
    return re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")


def main(argv: list[str] | None = None) -> int:
    """``python -m facepuppet.runtime.cli.reference [PATH]``: write the page to PATH, or to stdout."""
    cli = argparse.ArgumentParser(prog="python -m facepuppet.runtime.cli.reference",
                                  description="Write the commands reference (Markdown) from the argparse definitions.")
    cli.add_argument("path", nargs="?", type=Path, help="file to write (default: stdout)")
    args = cli.parse_args(argv)
    text = reference()
    if args.path is None:
        sys.stdout.write(text)
    else:
        write_atomic(args.path, lambda temp: temp.write_text(text, encoding="utf-8"))
        print(f"wrote {args.path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
