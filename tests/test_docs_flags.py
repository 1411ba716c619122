"""docs/cli.md names every flag of every ``gslam`` command, and no flag that
is gone: the argparse parsers of slam/cli.py are the reference."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import yaml

from slam.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
CLI_MD = ROOT / "docs" / "cli.md"
# Flags every command takes, documented once for all of them.
COMMON = {"-h", "--help", "-v", "--verbose", "-q", "--quiet"}
# Flags of other programs that the page quotes (ros2 run ... --ros-args).
FOREIGN = {"--ros-args"}
FLAG = re.compile(r"(?<![\w-])--?[a-zA-Z][\w-]*")


def _commands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


def _options(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {s: a for a in parser._actions for s in a.option_strings}


def _command_lines(text: str) -> list[str]:
    """Every ``gslam ...`` command the page writes: in inline code spans and
    in fenced code blocks (one command per line, comments cut)."""
    lines = []
    fenced = re.findall(r"^```[^\n]*\n(.*?)^```", text, flags=re.S | re.M)
    for block in fenced:
        for line in block.splitlines():
            line = line.split("#")[0].strip().removeprefix("$ ")
            if line.startswith("gslam "):
                lines.append(line)
    outside = re.sub(r"^```[^\n]*\n.*?^```", "", text, flags=re.S | re.M)
    lines += [span for span in re.findall(r"`([^`\n]+)`", outside) if span.startswith("gslam ")]
    return lines


def _flags_per_command(text: str, commands) -> dict[str, set[str]]:
    found: dict[str, set[str]] = {name: set() for name in commands}
    for line in _command_lines(text):
        words = line.split()
        if len(words) > 1 and words[1] in commands:
            found[words[1]] |= set(FLAG.findall(line))
    return found


def test_every_flag_of_every_command_is_documented():
    text = CLI_MD.read_text()
    commands = _commands()
    documented = _flags_per_command(text, commands)
    missing = {
        name: sorted(set(_options(p)) - COMMON - documented[name])
        for name, p in commands.items()
        if set(_options(p)) - COMMON - documented[name]
    }
    assert not missing, f"flags in --help but in no `gslam COMMAND ...` of docs/cli.md: {missing}"


def test_no_documented_flag_is_gone():
    text = CLI_MD.read_text()
    commands = _commands()
    wrong = {
        name: sorted(flags - set(_options(commands[name])))
        for name, flags in _flags_per_command(text, commands).items()
        if flags - set(_options(commands[name]))
    }
    assert not wrong, f"docs/cli.md gives commands flags they do not have: {wrong}"
    everywhere = set(FLAG.findall(" ".join(re.findall(r"`([^`]+)`", text))))
    known = {s for p in commands.values() for s in _options(p)} | set(_options(build_parser())) | FOREIGN
    stale = sorted(f for f in everywhere if f.startswith("--") and f not in known)
    assert not stale, f"docs/cli.md names flags no gslam command has: {stale}"


def test_the_choices_of_each_flag_are_documented():
    """A flag with a closed set of values is written ``--flag a|b|c`` with
    exactly those values."""
    text = CLI_MD.read_text()
    for name, parser in _commands().items():
        for flag, action in _options(parser).items():
            if not action.choices or not flag.startswith("--"):
                continue
            spelled = [s for s in re.findall(rf"`gslam {name} [^`]*{re.escape(flag)} ([\w|]+)", text) if "|" in s]
            assert spelled, f"docs/cli.md: gslam {name} {flag} does not list its values"
            assert {frozenset(s.split("|")) for s in spelled} == {frozenset(map(str, action.choices))}, spelled


def test_the_shipped_variants_are_documented():
    text = CLI_MD.read_text()
    compare = text[text.index("**`gslam compare"):]
    compare = compare[: compare.index("\n## ")]
    variants = yaml.safe_load((ROOT / "configs" / "variants.yaml").read_text())
    missing = [v for v in variants if f"`{v}`" not in compare]
    assert not missing, f"variants of configs/variants.yaml not named in docs/cli.md's gslam compare: {missing}"


def test_the_checker_finds_a_missing_and_a_stale_flag():
    """The checks above on a page with one flag dropped and one invented."""
    commands = _commands()
    text = CLI_MD.read_text().replace("[--keep-unsupported]", "[--keep-unsupportive]")
    documented = _flags_per_command(text, commands)
    assert "--keep-unsupported" not in documented["calibrate"]
    assert "--keep-unsupportive" in documented["calibrate"] - set(_options(commands["calibrate"]))
